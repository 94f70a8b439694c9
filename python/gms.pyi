"""gms: the friction models, identification, simulator and bench client of the gms project,
from the same Rust core as the firmware. Units are SI: s, m or rad, N or N·m, A, V."""

from os import PathLike
from typing import Any, Optional, Union

import numpy as np
import numpy.typing as npt

Params = Union[str, "PathLike[str]", dict[str, Any]]
"""A parameter file's path, or a dict with its keys ({"friction": {"model": "gms", ...}})."""

Scenario = Union[None, str, "PathLike[str]", dict[str, Any]]
"""None (the default scenario), a scenario file's path, or a dict with its keys."""

class GmsError(Exception):
    """Bad input (arrays, parameters, files), a fit that does not converge, or a device that
    refused or went silent; the message is the command line's one line."""

def friction(params: Params, t: npt.NDArray[np.float64], x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """The friction [N or N·m] along x(t) [m or rad; s] from the virgin state: what
    `hil-sim friction` computes for the same file (the same f32 model). Element 0 is 0.
    t strictly increasing, every value finite, equal lengths."""

class Model:
    """A friction model (gms, lugre or static) of a parameter file."""

    def __init__(self, params: Params) -> None: ...
    @property
    def kind(self) -> str:
        """"gms", "lugre" or "static"."""
    @property
    def force(self) -> float:
        """The friction after the last step [N or N·m]."""
    def step(self, dx: float, dt: float) -> float:
        """Moves by dx [m or rad] at constant velocity over dt [s]; returns the friction."""
    def run(self, t: npt.NDArray[np.float64], x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The friction along x(t) from the present state (element 0: the force before)."""
    def reset(self) -> None:
        """Back to the virgin state at rest."""
    @property
    def state(self) -> npt.NDArray[np.float64]:
        """Each Maxwell-slip block's force [N or N·m] (GMS), the bristle deflection z (LuGre),
        empty (static map)."""

class Gms(Model):
    """A GMS model (the file's model must be "gms")."""

class LuGre(Model):
    """A LuGre model (the file's model must be "lugre")."""

class StaticMap(Model):
    """A static friction map (the file's model must be "static")."""

def identify(presliding: Optional[Union[str, "PathLike[str]"]] = None, sliding: Optional[Union[str, "PathLike[str]"]] = None, lag: Optional[Union[str, "PathLike[str]"]] = None, blocks: int = 6, asymmetric: bool = False) -> dict[str, Any]:
    """The whole identification of `hil-sim identify` from its CSVs: {"params": the file's
    text, "friction": its [friction] table, "report", "virgin", "stribeck", "lag"}."""

def fit_virgin(x: npt.NDArray[np.float64], f: npt.NDArray[np.float64], blocks: int = 6) -> dict[str, Any]:
    """The virgin-curve fit (pre-sliding x [m or rad], f [N or N·m] from rest):
    {"blocks": [{"k", "alpha"}], "fs", "breakpoints", "rms"}."""

def fit_stribeck(v: npt.NDArray[np.float64], f: npt.NDArray[np.float64]) -> dict[str, Any]:
    """The Stribeck fit of steady sliding (v > 0 [m/s or rad/s], f): {"fs", "fc", "vs",
    "delta", "sigma", "rms", "std_err"}."""

def fit_lag(params: Params, t: npt.NDArray[np.float64], x: npt.NDArray[np.float64], f: npt.NDArray[np.float64]) -> dict[str, Any]:
    """The frictional-lag fit of C (the rest of the model from params): {"c", "rel_err", "rms"}."""

def run(scenario: Scenario = None) -> dict[str, Any]:
    """One closed-loop run as `hil-sim run`: {"trace": {column: array}, "metrics": {...},
    "mode", "seed"}; columns t, reference, position, error, current, current_cmd, voltage,
    friction, feedforward, ff_scale, drift, ref_velocity (SI)."""

def compare(scenario: Scenario = None, runs: int = 20, seed: int = 1) -> dict[str, Any]:
    """Every feedforward mode over `runs` friction draws, as `hil-sim compare` writes its JSON."""

def learn(scenario: Scenario = None, runs: int = 1, seed: int = 1, amplitude: float = 0.05, freq: float = 1.0, iterations: int = 10, gain: float = 0.15, q_filter: float = 300.0, lead: float = 0.0) -> dict[str, Any]:
    """Learning from repetition on the virtual device in-process over `runs` friction draws, as
    `hil-sim learn`: {"rms", "peak", "true_rms", "true_peak": arrays (run × iteration) [counts],
    "scatter_rms", "repeating", "not_repeating", "true_repeating", "true_not_repeating": arrays
    (one per run) [counts] — the best correction played 5 periods more, what of its error
    repeats and what does not —, "seeds", "stopped"}."""

class Device:
    """A board (serial port) or the virtual device (TCP) speaking the protocol, as gms-tune."""

    def __init__(self, port: Optional[str] = None, tcp: Optional[str] = None, timeout: float = 1.0) -> None: ...
    def request(self, line: str) -> str:
        """One protocol line; the reply's text (an `err` raises GmsError)."""
    def get(self, path: str) -> Union[float, str]: ...
    def set(self, path: str, value: Union[float, str]) -> None:
        """A refusal raises GmsError with the device's line; nothing changes."""
    def list(self) -> list[dict[str, str]]:
        """Every parameter: {"path", "value", "unit", "range"}."""
    def status(self) -> dict[str, Union[float, str]]: ...
    def record(self, fields: str = "t,pos,error,current", rate: float = 1000.0, seconds: float = 1.0) -> dict[str, npt.NDArray[np.float64]]:
        """The telemetry stream for `seconds` of wall time, as arrays by field."""
    def step_test(self, distance: float = 2e-4, seconds: float = 0.5) -> dict[str, Any]:
        """`gms-tune step-test`: {"trace": {t, ref, pos, error, ff, friction}, "metrics", "rad_per_count"}."""
    def tune_ff(self, amplitude: float = 2e-3, freq: float = 1.0, seconds: float = 3.0, start: float = 0.5, stop: float = 1.3, steps: int = 9) -> dict[str, Any]:
        """`gms-tune tune-ff`: {"curve": [(gain, rms)], "chosen", "before"}; nothing applied."""
    def commission(self, speed: float = 1.0) -> dict[str, Any]:
        """`gms-tune commission`: {"lines", "settings": {path: value}}; nothing applied."""
    def identify(self, report: Union[str, "PathLike[str]"] = "identify-report", blocks: int = 6) -> dict[str, Any]:
        """`gms-tune identify`: {"params", "report", "presliding", "sliding"}; nothing applied."""
    def learn(self, amplitude: float = 0.05, freq: float = 1.0, trajectory: Optional[list[tuple[float, float]]] = None, iterations: int = 10, gain: float = 0.15, q_filter: float = 300.0, lead: float = 0.0, apply: bool = False) -> dict[str, Any]:
        """`gms-tune learn`: {"rms", "peak" per iteration, "errors" (iteration × point), "t",
        "correction" [N·m], "repeating", "not_repeating" (over the last 5 iterations, counts;
        None with fewer than 3), "stopped"}; `apply` leaves the correction playing."""
