"""One schema: the plant parameter names, the MPC settings and the simulation come from the
core's single definitions; the stubs and the Python API are checked against them."""

import ast
from pathlib import Path

import riprs
from riprs.config import PARAMETERS

STUB = Path(riprs.__file__).with_name("_riprs.pyi")


def _stub():
    return ast.parse(STUB.read_text())


def _literal(tree, name):
    for node in tree.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", None) == name:
            sub = node.value
            assert isinstance(sub, ast.Subscript) and sub.value.id == "Literal"
            elts = sub.slice.elts if isinstance(sub.slice, ast.Tuple) else [sub.slice]
            return [e.value for e in elts]
    raise AssertionError(f"{name} not in the stub")


def _properties(tree, cls):
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == cls:
            return [
                f.name
                for f in node.body
                if isinstance(f, ast.FunctionDef)
                and any(getattr(d, "id", None) == "property" for d in f.decorator_list)
            ]
    raise AssertionError(f"{cls} not in the stub")


def test_the_stub_parameter_names_are_the_core_table():
    # PARAMETERS is the core's Param table ([plant] keys); the stub's Literal must list
    # exactly those, in the same order.
    assert _literal(_stub(), "_ParameterName") == list(PARAMETERS)
    assert len(PARAMETERS) == 15


def test_furuta_params_properties_are_the_core_fields():
    fields = list(riprs.FurutaParams.qube_servo2().to_dict())
    props = _properties(_stub(), "FurutaParams")
    assert props == fields
    # Every [plant] key is a field; the only other field is the gravitational acceleration.
    assert set(fields) - set(PARAMETERS) == {"g"}
    p = riprs.FurutaParams.qube_servo2()
    for name in fields:
        assert getattr(p, name) == p.to_dict()[name]
        changed = p.replace(**{name: 2.0 * getattr(p, name)})
        assert getattr(changed, name) == 2.0 * getattr(p, name)


def test_every_plant_key_reaches_the_plant_and_a_bad_one_is_named(tmp_path):
    base = riprs.Spec().plant.params.to_dict()
    for name in PARAMETERS:
        value = base[name] * 1.5 if base[name] else 1e-3
        f = tmp_path / f"{name}.toml"
        f.write_text(f"[plant]\n{name} = {value!r}\n")
        spec = riprs.load_config(f)
        got = spec.plant.params.to_dict()
        assert got[name] == value, name
        assert all(got[k] == base[k] for k in base if k != name), name
        f.write_text(f"[plant]\n{name} = -1.0\n")
        try:
            riprs.load_config(f)
        except riprs.ConfigError as e:
            assert f"plant.{name}" in str(e)
        else:
            raise AssertionError(f"plant.{name} = -1 accepted")


def test_mpc_paper_is_the_specs_mpc():
    import numpy as np

    a = riprs.Mpc.paper()
    b = riprs.Spec().build_controllers(0.01)["MPC"]
    assert a.solver == b.solver == riprs.Spec().mpc.solver == "active_set"
    assert a.prediction_horizon == b.prediction_horizon == 50
    x0, u0 = np.array([0.1, 0.0, 0.05, 0.0, 0.0]), [0.5]
    for x, y in zip(a.qp_matrices(x0, u0), b.qp_matrices(x0, u0), strict=True):
        np.testing.assert_array_equal(x, y)
    for k in range(200):
        y = [0.4 * np.sin(0.05 * k), 0.05 * np.cos(0.2 * k)]
        ua, ub = a.step(y, [1.0, 0.0]), b.step(y, [1.0, 0.0])
        assert ua.tobytes() == ub.tobytes(), k
    # MATLAB's defaults stay those of riprs.Mpc(...): P = 10, as MATLAB's mpc.
    m = riprs.paper.discrete_model()
    assert riprs.Mpc(m.A, m.B, m.C, 0.01).prediction_horizon == 10


def test_the_mpc_section_is_the_core_settings(tmp_path):
    # Spec.mpc is MpcSettings' serde form: the stub's attributes are exactly its keys, and a
    # file's [mpc] values come back as written (bounds as [min, max] lists).
    spec = riprs.Spec()
    assert sorted(_properties(_stub(), "MpcSpec")) == [k for k in dir(spec.mpc) if k[0] != "_"]
    f = tmp_path / "mpc.toml"
    f.write_text(
        "[mpc]\nprediction_horizon = 35\nsolver = 'clarabel'\n"
        "output_bounds = [[-1.0, 1.0], [-0.4, 0.4]]\n"
    )
    mpc = riprs.load_config(f).mpc
    assert (mpc.prediction_horizon, mpc.solver) == (35, "clarabel")
    assert mpc.output_bounds == [[-1.0, 1.0], [-0.4, 0.4]]
    assert mpc.control_horizon == spec.mpc.control_horizon
    try:
        getattr(mpc, "horizon")  # noqa: B009 (the attribute is looked up by name on purpose)
    except AttributeError as e:
        assert "prediction_horizon" in str(e)
    else:
        raise AssertionError("an unknown attribute was served")


def test_a_lab_start_restarts_measured_links_as_uniform_rods():
    # The uniform rod, J = m L^2 / 12, computed here from the definition.
    import importlib

    identify = importlib.import_module("riprs.identify")
    q = riprs.FurutaParams.qube_servo2()
    p = identify._apply_lab(q, {"mp": 0.06, "Lr": 0.1, "km": 0.05})
    assert abs(p.Jp - 0.06 * q.Lp**2 / 12) < 1e-15
    assert abs(p.Jr - q.mr * 0.1**2 / 12) < 1e-15
    assert (p.km, p.kt, p.Rm) == (0.05, 0.05, q.Rm)
    try:
        identify._apply_lab(q, {"mass": 0.1})
    except identify.IdentifyError as e:
        assert "lab.mass" in str(e)
    else:
        raise AssertionError("an unknown lab key was accepted")


def _paper_lqr_gain():
    import numpy as np
    import scipy.linalg

    m = riprs.paper.discrete_model()
    q, r = np.diag([25.0, 0.0, 50.0, 0.0]), np.array([[0.1]])
    x = scipy.linalg.solve_discrete_are(m.A, m.B, q, r)
    return np.linalg.solve(r + m.B.T @ x @ m.B, m.B.T @ x @ m.A)[0]


def test_compare_honours_the_encoder_offsets_as_an_offset_encoder_predicts(tmp_path):
    import numpy as np

    from riprs.compare import compare

    # An encoder reading angle + o: LQR u = -K (x_measured - x_ref) comes to rest where u = 0
    # with the pendulum upright (alpha = 0, the only equilibrium of the plant at u = 0), i.e.
    # K0 (theta + o0 - r) + K2 o1 = 0: theta_ss = r - o0 - (K2 / K0) o1 (scipy's DARE gain).
    k = _paper_lqr_gain()
    offsets = (0.2, 0.1)
    f = tmp_path / "offsets.toml"
    f.write_text("controllers = ['LQR']\n[sensor]\nencoder_offsets = [0.2, 0.1]\n")
    base = tmp_path / "base.toml"
    base.write_text("controllers = ['LQR']\n")
    runs = {}
    for name, path in (("offsets", f), ("base", base)):
        res = compare(path, plots=False, progress=False)
        runs[name] = res.runs["LQR"]
    r = riprs.Spec().reference.arm_step
    predicted = r - offsets[0] - k[2] / k[0] * offsets[1]
    tail = slice(-100, None)
    arm = {n: float(np.mean(run.x[tail, 0])) for n, run in runs.items()}
    assert abs(arm["base"] - r) < 0.01
    assert abs(predicted - r) > 0.1  # the prediction is a real change
    assert abs(arm["offsets"] - predicted) < 0.02, (arm, predicted)
    # The measured angles carry the offsets (the true pendulum stays upright).
    assert abs(float(np.mean(runs["offsets"].y[tail, 1])) - offsets[1]) < 0.01
    assert abs(float(np.mean(runs["offsets"].x[tail, 2]))) < 0.01


def test_compare_down_steps_reference_step_time_after_the_catch():
    import numpy as np

    spec = riprs.Spec.from_toml("[reference]\nstep_time = 0.5\n")
    down = spec.simulation_options("down")
    up = spec.simulation_options("up")
    assert down["step_after_catch"] == 0.5 and up["reference_time"] == 0.5
    assert down["duration"] == up["duration"] + riprs._riprs.SWING_UP_ALLOWANCE
    assert list(down["x0"]) == [0.0, 0.0, float(np.pi), 0.0]


def test_a_prbs_seed_is_a_u64_as_in_rip_rt():
    import numpy as np

    from riprs.excitation import excitation

    # The register starts at 1 + seed mod (2^bits - 1): the largest u64 seed that
    # `rip-rt excite --seed` takes regenerates, and equals the seed it reduces to.
    big = 2**64 - 1
    a = excitation("prbs", seed=big, prbs_bits=9)
    b = excitation("prbs", seed=big % 511, prbs_bits=9)
    c = excitation("prbs", seed=big % 511 + 1, prbs_bits=9)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    for bad in (2**64, -1):
        try:
            excitation("prbs", seed=bad)
        except riprs.InvalidParameterError as e:
            assert "seed" in str(e)
        else:
            raise AssertionError(f"seed {bad} accepted")


def test_a_deeply_nested_array_is_one_line_naming_the_file(tmp_path, capsys):
    from riprs.cli import main

    f = tmp_path / "deep.toml"
    f.write_text("[plant]\nmr = " + "[" * 3000 + "1" + "]" * 3000 + "\n[campaign]\nseeds = 1\n")
    for argv in (["campaign", str(f), "--out", str(tmp_path / "out")], ["config", str(f)]):
        assert main(argv) != 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(f) in err[0], err


def _python_sources():
    return sorted(Path(riprs.__file__).parent.rglob("*.py"))


def test_no_copy_of_the_parameter_table_in_the_package():
    # The [plant] keys come from the core's Param table (riprs.config.PARAMETERS); a literal
    # list of five or more of them is a second copy that can drift.
    names = set(PARAMETERS)
    copies = []
    for path in _python_sources():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
                found = [
                    e.value
                    for e in node.elts
                    if isinstance(e, ast.Constant) and e.value in names
                ]
                if len(found) >= 5:
                    copies.append(f"{path.name}:{node.lineno}: {found}")
    assert not copies, "\n".join(copies)


def test_the_voltage_bound_has_one_definition():
    # 12 V is rip-control's INPUT_LIMIT_MV (paper::INPUT_LIMIT in rip-core, DEFAULT_U_LIMIT in
    # Python, the device's and the firmware board's default); 24 V is the largest limit rip-rt
    # accepts (MAX_VOLTAGE_LIMIT, the emulated bridge's supply). No voltage setting, supply or
    # bound in the core, the no_std crates, rip-rt, the firmware or the package writes either
    # number again.
    import re

    root = Path(__file__).resolve().parents[1]
    pattern = re.compile(
        r"(volt|u_limit|u_max|_limit|supply|bound)\w*\s*[:=]\s*(?:\[?[\w:]*\(?\s*=?\s*)?"
        r"-?(12|24)(\.0|_?000)?\b",
        re.IGNORECASE,
    )
    sources = [*_python_sources()]
    for crate in ("rip-core", "rip-rt", "riprs-py", "rip-control", "rip-device", "rip-protocol"):
        sources += sorted((root / "crates" / crate / "src").rglob("*.rs"))
    sources += sorted((root / "firmware" / "src").rglob("*.rs"))
    hits = []
    for path in sources:
        text = path.read_text()
        if path.suffix == ".rs":
            # Only the code before a file's tests.
            text = text.split("#[cfg(test)]")[0]
        for line in text.splitlines():
            code = line.split("//")[0] if path.suffix == ".rs" else line.split("#")[0]
            if pattern.search(code):
                hits.append(f"{path.relative_to(root)}: {line.strip()}")
    assert hits == [
        "crates/rip-core/src/spec/rig_sections.rs: pub const MAX_VOLTAGE_LIMIT: f64 = 24.0;",
        "crates/rip-control/src/lib.rs: pub const INPUT_LIMIT_MV: u16 = 12_000;",
    ], "\n".join(hits)


def _rust_sources():
    """The non-test Rust sources of the crates and the firmware (test modules' own files
    left out; callers cut each file at its ``#[cfg(test)]``)."""
    root = Path(__file__).resolve().parents[1]
    files = [
        *sorted((root / "crates").glob("*/src/**/*.rs")),
        *sorted((root / "firmware" / "src").rglob("*.rs")),
    ]
    return root, [p for p in files if p.name != "tests.rs" and "tests" not in p.parts[-3:-1]]


def test_one_crc32_implementation():
    # CRC-32 is rip_protocol::crc32: the design image, the upload frames and the device check one
    # function. A second implementation carries the reflected polynomial again.
    root, sources = _rust_sources()
    hits = [
        str(p.relative_to(root))
        for p in sources
        if "0xedb88320" in p.read_text().lower().replace("_", "")
    ]
    assert hits == ["crates/rip-protocol/src/lib.rs"], hits


def test_no_copy_of_the_parameter_table_in_the_crates():
    # Rust lists of parameter names (any case: "lr" is Param::Lr's "Lr") are a second table that
    # can drift: the crates take their names from rip_core::plant::Param.
    import re

    names = {n.lower() for n in PARAMETERS} | {"g"}
    root, sources = _rust_sources()
    copies = []
    for path in sources:
        text = path.read_text().split("#[cfg(test)]")[0]
        for m in re.finditer(r"\[([^\[\]]*)\]", text):
            found = [s for s in re.findall(r'"(\w+)"', m.group(1)) if s.lower() in names]
            if len(found) >= 5:
                line = text[: m.start()].count("\n") + 1
                copies.append(f"{path.relative_to(root)}:{line}: {found}")
    assert not copies, "\n".join(copies)


def test_the_tuning_record_is_named_by_the_core(monkeypatch, tmp_path):
    # rip-rt finds the record by rip_core::preflight::tune_record_path; riprs.tune writes it by
    # the same function (a second naming rule in Python could drift from the loop's).
    import importlib

    tune = importlib.import_module("riprs.tune")  # the module, not riprs.tune the function
    assert tune.record_path(tmp_path / "rig.toml") == tmp_path / "rig.tune.toml"
    assert tune.record_path("x/rig") == Path("x/rig.tune.toml")
    monkeypatch.setattr(tune, "tune_record_path", lambda p: "core-named")
    assert tune.record_path(tmp_path / "rig.toml") == Path("core-named")


def test_the_default_encoder_resolution_has_one_definition():
    # 2048 counts per revolution is [sensor] encoder_counts' default (SensorSpec); [device]'s
    # counts and the emulator's take it from there.
    import re

    pattern = re.compile(r"counts\w*\s*[:=]\s*\[?2048\b")
    root, sources = _rust_sources()
    hits = []
    for path in sources:
        text = path.read_text().split("#[cfg(test)]")[0]
        for line in text.splitlines():
            if pattern.search(line.split("//")[0]):
                hits.append(f"{path.relative_to(root)}: {line.strip()}")
    assert hits == ["crates/rip-core/src/spec/sections.rs: encoder_counts: [2048, 2048],"], hits


RIG_FILE = """[plant]
preset = "qube_servo2"

[sensor]
encoder_counts = [1024, 512]

[safety]
voltage_limit = 6.0
arm_limit = 1.2

[device]
arm_sign = -1.0

[loop]
period_ms = 5.0
reply_timeout_ms = 2.0
"""


def test_a_file_riprs_writes_describes_the_rig_it_read(tmp_path, capsys):
    # rip-rt's sections survive load_config -> to_toml (what riprs config prints and riprs
    # tune writes): a 6 V motor's limit and a reversed encoder are not lost to the defaults.
    import tomllib

    from riprs.cli import main

    rig = tmp_path / "rig.toml"
    rig.write_text(RIG_FILE)
    spec = riprs.load_config(rig)
    text = spec.to_toml()
    doc = tomllib.loads(text)
    assert doc["safety"] == {"voltage_limit": 6.0, "arm_limit": 1.2}
    assert doc["device"] == {"arm_sign": -1.0}
    assert doc["loop"] == {"period_ms": 5.0, "reply_timeout_ms": 2.0}
    assert doc["sensor"]["encoder_counts"] == [1024, 512]
    assert riprs.Spec.from_toml(text) == spec
    written = tmp_path / "written.toml"
    written.write_text(text)
    assert riprs.load_config(written) == spec
    # An update keeps them, and is checked against them.
    assert tomllib.loads(spec.updated({"lqr": {"R": 0.2}}).to_toml())["safety"] == doc["safety"]
    assert main(["config", str(rig)]) == 0
    assert tomllib.loads(capsys.readouterr().out)["safety"] == doc["safety"]
    # Without rip-rt sections nothing is added.
    assert "safety" not in tomllib.loads(riprs.Spec().to_toml())


def test_a_written_rig_file_reads_the_same_in_rip_rt(tmp_path, rip_rt):
    import subprocess

    rig = tmp_path / "rig.toml"
    rig.write_text(RIG_FILE)
    written = tmp_path / "written.toml"
    written.write_text(riprs.load_config(rig).to_toml())
    outs = [
        subprocess.run([str(rip_rt), "config", str(p)], capture_output=True, text=True, timeout=60)
        for p in (rig, written)
    ]
    assert all(o.returncode == 0 for o in outs), [o.stderr for o in outs]
    assert outs[0].stdout == outs[1].stdout
    assert "voltage_limit = 6" in outs[1].stdout
