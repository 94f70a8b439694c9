"""Identify a friction from a simulated experiment with the gms Python package, and plot it.

    pip install ./python matplotlib
    python docs/examples/identify.py            # writes identify.png

The experiment: Table 1's GMS model (examples/table1.toml) driven by a slow ramp from rest
(the pre-sliding virgin curve) and by constant speeds (the Stribeck curve); the fits are the
ones `hil-sim identify` runs; the plot shows data and fits.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import gms

root = Path(__file__).resolve().parents[2]
params = str(root / "examples" / "table1.toml")

# Pre-sliding: 6 mrad in 10 s from rest.
t = np.linspace(0.0, 10.0, 400)
x = np.linspace(0.0, 6e-3, 400)
f = gms.friction(params, t, x)
virgin = gms.fit_virgin(x[1:], f[1:], 6)

# Sliding: the steady friction at 12 speeds.
v = np.geomspace(0.02, 6.0, 12)
fv = []
for vi in v:
    m = gms.Model(params)
    tt = np.linspace(0.0, 0.5, 2001)
    fv.append(m.run(tt, vi * tt)[-1])
stribeck = gms.fit_stribeck(v, np.array(fv))
print(f"Fs {stribeck['fs']:.4e} Fc {stribeck['fc']:.4e} N·m, Vs {stribeck['vs']:.4f} rad/s, "
      f"delta {stribeck['delta']:.3f}; virgin curve rms {virgin['rms']:.2e} N·m")

fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
a.plot(x * 1e3, f * 1e6, ".", label="model")
xs = np.linspace(0.0, x.max(), 300)
fit = sum(np.minimum(blk["k"] * xs, blk["alpha"] * virgin["fs"]) for blk in virgin["blocks"])
a.plot(xs * 1e3, fit * 1e6, label="6-block fit")
a.set(xlabel="displacement [mrad]", ylabel="friction [µN·m]", title="virgin curve")
a.legend()
vs = np.geomspace(v.min(), v.max(), 200)
s = stribeck
sv = s["fc"] + (s["fs"] - s["fc"]) * np.exp(-((vs / s["vs"]) ** s["delta"])) + s["sigma"] * vs
b.semilogx(v, np.array(fv) * 1e6, "o", label="steady sliding")
b.semilogx(vs, sv * 1e6, label="Stribeck fit")
b.set(xlabel="speed [rad/s]", ylabel="friction [µN·m]", title="Stribeck curve")
b.legend()
fig.tight_layout()
fig.savefig("identify.png", dpi=100)
print("wrote identify.png")
