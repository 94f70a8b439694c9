"""The Python package against the command line it shares its code with (`hil-sim friction`,
`hil-sim run`, `hil-sim serve`), and against physics it must reproduce."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import gms

ROOT = Path(__file__).resolve().parents[2]
TABLE1 = ROOT / "examples" / "table1.toml"


def hil_sim_cmd():
    """The `hil-sim` command: `$HIL_SIM` when set (a built binary: CI passes the test build's,
    which `cargo run -p hil-sim` would build again with the features of that package alone),
    else through cargo from the repository's root."""
    exe = os.environ.get("HIL_SIM")
    return [exe] if exe else ["cargo", "run", "-q", "-p", "hil-sim", "--"]


def hil_sim(*args, **kw):
    """`hil-sim ARGS`."""
    return subprocess.run(
        [*hil_sim_cmd(), *map(str, args)],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
        **kw,
    )


def read_csv(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def test_friction_is_hil_sim_friction(tmp_path):
    traj = read_csv(ROOT / "examples" / "trajectory.csv")
    out = tmp_path / "f.csv"
    hil_sim("friction", "--params", TABLE1, "--input", ROOT / "examples" / "trajectory.csv", "--output", out)
    cli = read_csv(out)
    f = gms.friction(str(TABLE1), traj["t"], traj["x"])
    assert f.shape == cli["f"].shape
    # The same f32 model: the same bits (the CLI prints the f32 shortest form).
    assert np.array_equal(np.float32(f), np.float32(cli["f"]))
    # The parameter file as a dict gives the same.
    import tomllib

    with open(TABLE1, "rb") as fh:
        params = tomllib.load(fh)
    assert np.array_equal(gms.friction(params, traj["t"], traj["x"]), f)


def test_friction_is_hil_sim_friction_bit_for_bit_on_random_17_digit_inputs(tmp_path):
    # Random trajectories written with 17 significant digits (every f64 round-trips): the
    # CSV's f, read as f64 as any reader would, equals gms.friction's exactly (the CLI writes
    # the f64 of the model's f32, not the f32's shortest text, which is another f64).
    rng = np.random.default_rng(24)
    for trial in range(5):
        n = 400
        t = np.cumsum(rng.uniform(1e-4, 5e-3, n))
        x = np.cumsum(rng.normal(0.0, 3e-4, n)) + 1e-3 * np.sin(40 * t)
        path = tmp_path / f"traj{trial}.csv"
        with open(path, "w") as fh:
            fh.write("t,x\n")
            for a, b in zip(t, x):
                fh.write(f"{a:.17g},{b:.17g}\n")
        out = tmp_path / f"f{trial}.csv"
        hil_sim("friction", "--params", TABLE1, "--input", path, "--output", out)
        cli = read_csv(out)
        assert np.array_equal(cli["t"], t) and np.array_equal(cli["x"], x)
        f = gms.friction(str(TABLE1), t, x)
        assert np.array_equal(f, cli["f"]), np.max(np.abs(f - cli["f"]))


def test_model_objects_step_run_and_reset():
    m = gms.Model(str(TABLE1))
    assert m.kind == "gms"
    t = np.linspace(0.0, 1.0, 101)
    x = 2e-3 * np.sin(2 * np.pi * t)
    a = m.run(t, x)
    assert np.array_equal(a, gms.friction(str(TABLE1), t, x))
    assert m.force == pytest.approx(a[-1])
    m.reset()
    assert m.force == 0.0
    # Steps of the same motion give the same friction.
    for i in range(1, len(t)):
        last = m.step(x[i] - x[i - 1], t[i] - t[i - 1])
    assert last == a[-1]


def test_identification_round_trip_from_arrays():
    # The virgin curve: a slow ramp from rest with Table 1's model.
    t = np.linspace(0.0, 10.0, 400)
    x = np.linspace(0.0, 6e-3, 400)
    f = gms.friction(str(TABLE1), t, x)
    fit = gms.fit_virgin(x[1:], f[1:], 6)
    assert len(fit["blocks"]) == 6
    assert sum(b["alpha"] for b in fit["blocks"]) == pytest.approx(1.0, abs=1e-6)
    assert fit["rms"] < 0.01 * f.max()
    # The Stribeck curve: steady sliding at each speed (the model run long enough to settle).
    v = np.geomspace(0.02, 6.0, 12)
    fv = []
    for vi in v:
        m = gms.Model(str(TABLE1))
        tt = np.linspace(0.0, 0.5, 2001)
        fv.append(m.run(tt, vi * tt)[-1])
    s = gms.fit_stribeck(v, np.array(fv))
    assert s["fs"] == pytest.approx(220e-6, rel=0.01)
    assert s["fc"] == pytest.approx(125e-6, rel=0.01)
    assert s["vs"] == pytest.approx(0.2, rel=0.02)


def test_run_is_hil_sim_run(tmp_path):
    res = gms.run()
    hil_sim("run", "--out", tmp_path)
    with open(tmp_path / "metrics.json") as fh:
        cli = json.load(fh)
    for k, v in cli["metrics"].items():
        assert res["metrics"][k] == pytest.approx(v, rel=1e-12, abs=1e-15), k
    assert res["mode"] == cli["mode"] and res["seed"] == cli["seed"]
    tr = res["trace"]
    assert len(tr["t"]) == len(tr["error"]) > 1000
    assert np.all(np.diff(tr["t"]) > 0)


def serve(*args):
    """`hil-sim serve --tcp 127.0.0.1:0 ARGS`: the process and its address."""
    p = subprocess.Popen(
        [*hil_sim_cmd(), "serve", "--tcp", "127.0.0.1:0", *map(str, args)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    line = p.stdout.readline()
    assert line.startswith("listening on "), line
    return p, line.split()[-1]


@pytest.fixture
def server():
    p, addr = serve()
    yield addr
    p.kill()
    p.wait()


def test_device_against_the_virtual_device(server):
    d = gms.Device(tcp=server, timeout=2.0)
    assert d.get("pos.kp") == 0.49
    d.set("pos.kd", 2.2e-4)
    assert d.get("pos.kd") == pytest.approx(2.2e-4)
    with pytest.raises(gms.GmsError, match="err 6"):
        d.set("pos.kp", 5000)
    assert d.get("pos.kp") == 0.49
    assert d.get("ff.mode") == "gms"
    paths = [p["path"] for p in d.list()]
    assert "gms.fs" in paths and "pos.kp" in paths
    st = d.status()
    assert st["enabled"] == 0 and st["fault_names"] == "none"
    rec = d.record("t,pos", 1000.0, 0.5)
    assert len(rec["t"]) > 100
    assert np.all(np.diff(rec["t"]) > 0)


def test_bad_inputs_raise_clear_errors(tmp_path):
    t = np.linspace(0.0, 1.0, 5)
    with pytest.raises(gms.GmsError, match="different lengths"):
        gms.friction(str(TABLE1), t, t[:3])
    x = t.copy()
    x[2] = np.nan
    with pytest.raises(gms.GmsError, match="finite"):
        gms.friction(str(TABLE1), t, x)
    with pytest.raises(gms.GmsError, match="does not increase"):
        gms.friction(str(TABLE1), t[::-1], t)
    with pytest.raises(TypeError):
        gms.friction(str(TABLE1), np.zeros((2, 2)), np.zeros((2, 2)))
    bad = {"friction": {"model": "gms", "fs": 1e-4, "fc": 2e-4, "vs": 0.1, "c": 1e-3,
                        "blocks": [{"k": 1.0, "alpha": 1.0}]}}
    with pytest.raises(gms.GmsError, match=r"\[friction\] fs must be >= fc"):
        gms.friction(bad, t, t)
    with pytest.raises(gms.GmsError, match="needs `sigma0`"):
        gms.Model({"friction": {"model": "lugre", "fs": 2e-4, "fc": 1e-4, "vs": 0.1}})
    with pytest.raises(gms.GmsError, match="missing.toml"):
        gms.Model(str(tmp_path / "missing.toml"))
    with pytest.raises(gms.GmsError):
        gms.fit_stribeck(np.array([1.0, 2.0]), np.array([1.0]))
    with pytest.raises(gms.GmsError, match="port or tcp"):
        gms.Device()


def test_compare_is_hil_sim_compare(tmp_path):
    res = gms.compare(None, runs=2, seed=1)
    hil_sim("compare", "--runs", 2, "--seed", 1, "--json", tmp_path / "c.json")
    with open(tmp_path / "c.json") as fh:
        cli = json.load(fh)
    assert json.dumps(res, sort_keys=True) == json.dumps(cli, sort_keys=True)


def test_model_classes_and_state():
    g = gms.Gms(str(TABLE1))
    assert isinstance(g, gms.Model) and g.kind == "gms"
    assert len(g.state) == 6 and not g.state.any()
    g.step(3e-4, 0.01)
    # At rest (a hold step: no viscous part) the friction is the sum of the block forces.
    f = g.step(0.0, 0.01)
    assert f == pytest.approx(float(np.sum(np.float32(g.state))), rel=1e-6)
    assert np.all(g.state > 0)
    g.reset()
    assert not g.state.any()
    with pytest.raises(gms.GmsError, match="a gms model, not lugre"):
        gms.LuGre(str(TABLE1))
    lug = gms.LuGre({"friction": {"model": "lugre", "fs": 2e-4, "fc": 1e-4, "vs": 0.1,
                                  "sigma0": 1.0, "sigma1": 1e-3}})
    lug.step(1e-5, 0.01)
    assert len(lug.state) == 1 and lug.state[0] > 0


def test_identify_is_hil_sim_identify(tmp_path):
    pre, slide, out = tmp_path / "pre.csv", tmp_path / "slide.csv", tmp_path / "id.toml"
    hil_sim("experiment", "presliding", "--params", TABLE1, "--out", pre)
    hil_sim("experiment", "sliding", "--params", TABLE1, "--out", slide)
    hil_sim("identify", "--presliding", pre, "--sliding", slide, "--out", out)
    res = gms.identify(presliding=pre, sliding=slide)
    import tomllib

    with open(out, "rb") as fh:
        cli = tomllib.load(fh)
    assert tomllib.loads(res["params"])["friction"] == cli["friction"]
    # The simulated experiments' defaults (the CLI's own figures): Table 1 within a few %.
    assert res["friction"]["fs"] == pytest.approx(220e-6, rel=0.03)
    assert res["stribeck"]["vs"] == pytest.approx(0.2, rel=0.05)
    assert len(res["virgin"]["blocks"]) == 6 and res["report"]
    with pytest.raises(gms.GmsError):
        gms.identify(presliding=tmp_path / "none.csv")


def test_device_runs_the_bench_experiments(tmp_path):
    import tomllib

    # The default plant, its friction exactly nominal and the guideway negligible, 20 x real time.
    sc = tmp_path / "quiet.toml"
    sc.write_text("[plant]\nvariability = 0.0\n[plant.guideway]\nfs = 1e-6\nfc = 1e-6\n")
    p, addr = serve("--speed", 20, "--scenario", sc)
    try:
        d = gms.Device(tcp=addr, timeout=2.0)
        st = d.step_test(2e-4, 0.5)
        assert len(st["trace"]["t"]) > 100
        assert st["metrics"]["steady_state_error"] < 2 * 3.8e-6
        # The device's resolution, the paper's encoder that the default plant has.
        assert st["rad_per_count"] == pytest.approx(3.8e-6, rel=1e-9)
        ff = d.tune_ff(seconds=2.0, steps=5)
        # 5 coarse tests (more if widened), then 9 gains twice around the optimum.
        assert len(ff["curve"]) >= 5 + 18 and ff["optimum"] is not None
        assert ff["decided"] and ff["chosen"] == ff["optimum"] and ff["standard_error"] < 0.05
        assert d.get("ff.gain") == 0.94
        # The current path's resistance: the winding's 10 ohm and the default plant's bridge
        # switches' 0.565 (the simulated device's default describes them too).
        c = d.commission(1.0)
        assert c["settings"]["motor.r"] == pytest.approx(10.565, rel=0.05)
        assert c["settings"]["enc.dir"] == 1.0 and c["lines"]
        assert d.get("motor.r") == pytest.approx(10.565, rel=1e-6)
        rep = tmp_path / "rep"
        idf = d.identify(report=rep)
        fr = tomllib.loads(idf["params"])["friction"]
        assert fr["fs"] == pytest.approx(220e-6, rel=0.05)
        assert (rep / "presliding.csv").exists() and (rep / "sliding.csv").exists()
        assert d.status()["enabled"] == 0
    finally:
        p.kill()
        p.wait()


def test_device_frf_returns_arrays_and_margins(tmp_path):
    # The default plant, nominal, 20 x real time: the plant at rest shows the pre-sliding
    # spring (the actuator's blocks, Σk 1.2477 N·m/rad, and the guideway's, 2e-4 reflected);
    # the open loop its margins (the default gains: the linear model's 47.9° at rest, its
    # phase crossing near 3.4 kHz, above this sweep's 3 kHz: no gain margin in the band).
    # The inertia is the fit's curvature over the few points below half the resonance: with
    # 12 points and 3 mA the default loop holds the axis within a few counts there and the
    # fit reads it 14 % low (hil-sim's frf test holds the estimator to 8 % on 40 points).
    # The ideal bridge, as hil-sim's frf tests: at rest the real bridge's dead time is a
    # non-linearity about zero current that the linear model has not (Σk read +4.9 %).
    sc = tmp_path / "nominal.toml"
    sc.write_text("[plant]\nvariability = 0.0\n[plant.bridge]\nideal = true\n")
    p, addr = serve("--speed", 20, "--scenario", sc)
    try:
        d = gms.Device(tcp=addr, timeout=2.0)
        pl = d.frf("plant", start=20.0, stop=2000.0, points=12, amplitude=0.003)
        assert len(pl["f_hz"]) == 12 and np.all(np.diff(pl["f_hz"]) > 0)
        # Above ~1.5 kHz the position's response to 3 mA nears the encoder's count.
        assert np.sum(pl["coherence"] > 0.9) >= 10
        k, j = pl["presliding"]
        assert k == pytest.approx(1.2477 + 2.0e-4, rel=0.03)
        assert j == pytest.approx(6e-8, rel=0.25)
        assert pl["margins"] is None
        ol = d.frf("open", start=20.0, stop=3000.0, points=16, amplitude=0.003)
        m = ol["margins"]
        assert abs(m["phase_margin_deg"] - 47.9) < 5.0 and m["gain_margin_db"] > 6.0
        assert len(ol["gain_db"]) > 16  # the refinement around the crossings
        with pytest.raises(gms.GmsError, match="Nyquist"):
            d.frf("open", stop=9500.0)
        with pytest.raises(gms.GmsError, match="lim.i_max"):
            d.frf("plant", amplitude=5.0)
        assert d.status()["enabled"] == 0
        assert d.get("pos.kp") == 0.49
    finally:
        p.kill()
        p.wait()


def test_device_map_finds_the_ripple_and_round_trips_the_table(tmp_path):
    # A direct-drive screw with a hidden 12/rev cogging (20 µN·m) and a ±10 % once-per-rev
    # friction; 20 x real time.
    sc = tmp_path / "ripple.toml"
    sc.write_text(
        "[plant]\nvariability = 0.0\ngear_ratio = 1.0\nlead = 1.13636e-4\n"
        "[plant.ripple]\namplitude = 20e-6\nper_rev = 12\nscrew_friction = 0.1\n"
        "[plant.guideway]\nfs = 1e-6\nfc = 1e-6\n[controller.ff]\nguideway = false\n"
    )
    p, addr = serve("--speed", 20, "--scenario", sc)
    try:
        d = gms.Device(tcp=addr, timeout=2.0)
        m = d.map(bins=256, order=48, apply=True)
        assert len(m["angle"]) == 256
        truth = 20e-6 * np.sin(12 * m["angle"])
        assert np.sqrt(np.mean((m["offset"] - truth) ** 2)) < 0.1 * np.sqrt(np.mean(truth**2))
        assert np.max(np.abs(m["scale"] - (1.0 + 0.1 * np.sin(m["angle"])))) < 0.05
        assert d.get("map.enable") == 1 and d.get("map.bins") == 256
        o, s = d.map_read()
        assert np.allclose(o, m["offset"], rtol=1e-6, atol=1e-12)
        assert np.allclose(s, m["scale"], rtol=1e-6)
        with pytest.raises(gms.GmsError, match="map.enable is 1"):
            d.request("map clear")
        with pytest.raises(gms.GmsError, match="different lengths"):
            d.map_write(np.zeros(8), np.ones(9))
        d.map_write(np.zeros(8), np.ones(8), enable=False)
        assert d.get("map.bins") == 8 and d.get("map.enable") == 0
    finally:
        p.kill()
        p.wait()


def test_learn_in_the_simulator_lowers_the_error_against_the_truth():
    # The learning on the virtual device in-process, one friction draw: the device's RMS and
    # the one against the simulated true position, per iteration.
    r = gms.learn(runs=1, seed=1, iterations=6)
    assert r["rms"].shape == (1, 7) and r["true_rms"].shape == (1, 7)
    assert r["stopped"] == [None]
    # The encoder reads the floor of the angle: the true error is the device's within a count.
    assert np.all(np.abs(r["rms"] - r["true_rms"]) < 0.3)
    assert np.mean(r["rms"][0, 3:]) < r["rms"][0, 0]
    # After it, what repeats and what does not: their squares make the whole, against the
    # reading; against the truth less scatters (no quantisation).
    rep, nonrep, whole = r["repeating"][0], r["not_repeating"][0], r["scatter_rms"][0]
    assert 0.0 < rep < whole and 0.0 < nonrep < whole
    assert abs(rep**2 + nonrep**2 - whole**2) < 1e-9 * whole**2
    assert 0.0 < r["true_not_repeating"][0] < nonrep
    with pytest.raises(gms.GmsError, match="gain"):
        gms.learn(gain=5.0)


def test_device_learn_returns_the_iterations_and_leaves_the_correction_on_request():
    p, addr = serve("--speed", 20)
    try:
        d = gms.Device(tcp=addr, timeout=2.0)
        r = d.learn(iterations=2)
        assert len(r["rms"]) == 3 and len(r["peak"]) == 3
        assert r["errors"].shape == (3, 1000)
        assert len(r["correction"]) == 1000 and r["t"][1] == pytest.approx(1e-3)
        # Over the three iterations, what repeats and what does not make the mean square.
        ms = np.mean(r["rms"] ** 2)
        assert r["repeating"] ** 2 + r["not_repeating"] ** 2 == pytest.approx(ms, rel=1e-9)
        assert "gen=0 " in d.request("table")
        r = d.learn(iterations=1, apply=True)
        assert r["not_repeating"] is None
        assert "gen=0 " not in d.request("table")
        with pytest.raises(gms.GmsError, match="soft limits"):
            d.learn(trajectory=[(0.0, 0.0), (3.0, 30.0), (6.0, 60.0), (12.0, 0.0)])
    finally:
        p.kill()
        p.wait()
