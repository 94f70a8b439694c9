"""Fits the polynomial P in e^r = 1 + r + r^2 P(r), |r| <= ln(2)/2, for least maximum relative
error (Lawson's iteration on a least-squares fit). Prints the max relative error before f32
rounding and the coefficients used in gms-core/src/math.rs (EXP_P). Needs numpy."""
import numpy as np

a = np.log(2) / 2
r = np.cos(np.linspace(0, np.pi, 4001)) * a
r = r[np.abs(r) > 1e-12]
y = (np.exp(r) - 1 - r) / r**2
w = r**2 / np.exp(r)  # turns the fit's absolute error into relative error of e^r
V = np.vander(r, 4, increasing=True)
W = np.ones_like(r)
for _ in range(200):
    c, *_ = np.linalg.lstsq(V * (w * np.sqrt(W))[:, None], y * w * np.sqrt(W), rcond=None)
    e = np.abs((1 + r + r**2 * (V @ c)) / np.exp(r) - 1)
    W = W * e
    W /= W.sum()
e = np.abs((1 + r + r**2 * (V @ c)) / np.exp(r) - 1)
print("max relative error", e.max())
print("EXP_P", [float(np.float32(x)) for x in c])

# 2^f = 1 + f Q(f), |f| <= 1/2, Q of degree 4 (EXP2_P), same method.
f = np.cos(np.linspace(0, np.pi, 4001)) * 0.5
y2 = 2.0**f
V2 = np.vander(f, 6, increasing=True)[:, 1:]
W = np.ones_like(f)
for _ in range(300):
    w = np.sqrt(W) / y2
    c2, *_ = np.linalg.lstsq(V2 * w[:, None], (y2 - 1) * w, rcond=None)
    e = np.abs((1 + V2 @ c2) / y2 - 1)
    W = W * e
    W /= W.sum()
c32 = np.float32(c2).astype(np.float64)
print("max relative error (f32 coefficients)", np.abs((1 + V2 @ c32) / y2 - 1).max())
print("EXP2_P", [float(np.float32(x)) for x in c2])
