"""The Python package against the shipped specs and models: check, verify
and certify, the report as Python objects and the sets as NumPy arrays,
controllers as bytes, diagnostics as RavelError, the GIL released, hostile
inputs, and the training example. Run by scripts/test-python.sh."""

import json
import os
import pathlib
import shutil
import subprocess
import sys
import threading

import numpy as np
import onnx
import pytest
from onnx import numpy_helper

import ravel

REPO = pathlib.Path(__file__).resolve().parents[3]
SPECS = REPO / "specs"
MODELS = REPO / "models"
DI = SPECS / "double_integrator.ravel"
DI_MODEL = MODELS / "double_integrator.onnx"
EXAMPLE = REPO / "examples" / "python" / "train_until_verified.py"

sys.path.insert(0, str(EXAMPLE.parent))
from train_until_verified import mlp_onnx_bytes  # noqa: E402


def expected(spec):
    """The verdict or codes a shipped spec's first line states."""
    first = spec.read_text().splitlines()[0]
    assert first.startswith("// expect: ")
    return first[len("// expect: "):].split()


def layers_of(path):
    """(W, b) per Gemm of a model file, as float64 arrays."""
    model = onnx.load(str(path))
    init = {t.name: numpy_helper.to_array(t).astype(np.float64) for t in model.graph.initializer}
    return [(init[n.input[1]], init[n.input[2]]) for n in model.graph.node if n.op_type == "Gemm"]


def forward(layers, x):
    for i, (w, b) in enumerate(layers):
        x = x @ w.T + b
        if i + 1 < len(layers):
            x = np.maximum(x, 0.0)
    return x


# --- check -----------------------------------------------------------------


def test_check_a_system_spec():
    assert ravel.check(str(DI)) == "system"


def test_check_a_network_spec_given_as_a_pathlike():
    assert ravel.check(SPECS / "network" / "classifier_robust.ravel") == "network"


def test_check_a_spec_given_as_text_reads_its_controller_from_directory():
    assert ravel.check(text=DI.read_text(), directory=SPECS) == "system"


def test_check_text_without_directory_reads_relative_to_the_working_folder(monkeypatch):
    monkeypatch.chdir(SPECS)
    assert ravel.check(text=DI.read_text()) == "system"


INVALID = sorted((SPECS / "invalid").glob("*.ravel"))


@pytest.mark.parametrize("spec", INVALID[:12], ids=lambda p: p.stem)
def test_invalid_specs_raise_their_documented_codes(spec):
    with pytest.raises(ravel.RavelError) as e:
        ravel.check(spec)
    codes = [d["code"] for d in e.value.diagnostics]
    assert sorted(set(codes)) == sorted(set(expected(spec)))
    assert e.value.code == codes[0]
    for d in e.value.diagnostics:
        assert d["code"] in str(e.value)


def test_a_syntax_error_has_its_span_line_and_column():
    text = "system s {\n    state x[2]\n    bogus!\n}\n"
    with pytest.raises(ravel.RavelError) as e:
        ravel.check(text=text)
    err = e.value
    assert err.code == "E0001"
    assert err.span is not None
    assert err.span["line"] == 3
    assert text[err.span["start"]:].startswith("bogus") or err.span["column"] >= 5
    assert err.message
    assert "<text>" in str(err)


def test_a_check_error_carries_a_hint():
    spec = SPECS / "invalid" / "actuate_wrong_length.ravel"
    with pytest.raises(ravel.RavelError) as e:
        ravel.check(spec)
    assert any(d["hint"] for d in e.value.diagnostics)
    assert all(d["span"] is None or d["span"]["end"] >= d["span"]["start"] for d in e.value.diagnostics)


def test_errors_never_echo_control_characters():
    text = DI.read_text().replace("system double_integrator", "system di\x1b[31m\x07\x00")
    with pytest.raises(ravel.RavelError) as e:
        ravel.check(text=text, directory=SPECS)
    shown = str(e.value) + repr(e.value.diagnostics)
    for c in ("\x1b", "\x07", "\x00"):
        assert c not in str(e.value)
    assert "\x1b" not in shown


def test_a_missing_spec_file_is_a_ravel_error_without_code():
    with pytest.raises(ravel.RavelError) as e:
        ravel.check(SPECS / "no_such_spec.ravel")
    assert e.value.code is None and e.value.span is None
    assert "cannot read spec" in str(e.value)


def test_a_folder_is_not_a_spec():
    with pytest.raises(ravel.RavelError) as e:
        ravel.check(SPECS)
    assert "folder" in str(e.value)


def test_spec_path_and_text_together_are_refused():
    with pytest.raises(TypeError):
        ravel.check(DI, text="x")
    with pytest.raises(TypeError):
        ravel.check()


# --- verify ----------------------------------------------------------------


def test_verify_verified_with_reach_sets_as_arrays():
    r = ravel.verify(DI)
    assert r.verdict == "VERIFIED" == r["verdict"]
    assert r.json["spec"] == str(DI)
    assert r.lower.dtype == np.float64 and r.lower.shape == (6, 2) == r.upper.shape
    # step 0 is the initial set X0
    assert np.all(r.lower[0] <= [2.5, -0.25]) and np.all(r.upper[0] >= [3.0, 0.25])
    assert np.all(r.lower <= r.upper)
    # the arrays are the JSON's boxes, to the bit
    for t, step in enumerate(r.json["reachable"]):
        assert list(r.lower[t]) == step["box"]["lo"]
        assert list(r.upper[t]) == step["box"]["hi"]


def test_reach_sets_contain_simulated_trajectories():
    r = ravel.verify(DI)
    layers = layers_of(DI_MODEL)
    a, b = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[0.5], [1.0]])
    rng = np.random.default_rng(1)
    x = rng.uniform([2.5, -0.25], [3.0, 0.25], size=(500, 2))
    x = np.vstack([x, [[2.5, -0.25], [2.5, 0.25], [3.0, -0.25], [3.0, 0.25]]])
    for t in range(6):
        assert np.all(x >= r.lower[t] - 1e-12) and np.all(x <= r.upper[t] + 1e-12), t
        u = np.clip(forward(layers, x), -1.0, 1.0)
        x = x @ a.T + u @ b.T


def test_cells_are_inside_the_reachable_box():
    r = ravel.verify(SPECS / "double_integrator_partitioned.ravel")
    cells = r.cell_lower.shape[0]
    assert cells > 1 and r.cell_lower.shape == (cells, r.lower.shape[0], 2) == r.cell_upper.shape
    assert np.all(r.cell_lower >= r.lower[None, :, :]) and np.all(r.cell_upper <= r.upper[None, :, :])


def test_verify_falsified_gives_a_counterexample():
    spec = SPECS / "double_integrator_falsified.ravel"
    assert expected(spec) == ["FALSIFIED"]
    r = ravel.verify(spec)
    assert r.verdict == "FALSIFIED"
    falsified = [p for p in r["properties"] if p["status"] == "FALSIFIED"]
    assert falsified and falsified[0]["counterexample"]["states"]


def test_verify_unsure():
    spec = SPECS / "double_integrator_ibp.ravel"
    assert expected(spec) == ["UNSURE"]
    assert ravel.verify(spec).verdict == "UNSURE"


def test_a_time_limit_of_zero_is_sound_unsure():
    r = ravel.verify(DI, time_limit=0)
    assert r.verdict == "UNSURE"
    assert np.isinf(r.upper[-1]).all()


def test_threads_do_not_change_the_report():
    spec = SPECS / "double_integrator_partitioned.ravel"
    one, two = ravel.verify(spec, jobs=1), ravel.verify(spec, jobs=2)
    assert one.json == two.json
    assert np.array_equal(one.cell_upper, two.cell_upper)


def test_a_network_spec_bounds_its_outputs():
    spec = SPECS / "network" / "classifier_robust.ravel"
    r = ravel.verify(spec)
    assert r.verdict == "VERIFIED"
    assert r.lower.shape == (3,) == r.upper.shape
    layers = layers_of(MODELS / "classifier.onnx")
    rng = np.random.default_rng(2)
    x = np.array([0.6, 0.3]) + rng.uniform(-0.05, 0.05, size=(1000, 2))
    y = forward(layers, x)
    assert np.all(y >= r.lower - 1e-9) and np.all(y <= r.upper + 1e-9)


def test_the_report_is_the_command_lines_json():
    binary = os.environ.get("RAVEL_BIN") or shutil.which("ravel")
    if not binary or not os.path.exists(binary):
        pytest.skip("the ravel binary is not built (scripts/test-python.sh sets RAVEL_BIN)")
    spec = SPECS / "double_integrator_falsified.ravel"
    out = subprocess.run(
        [binary, "verify", str(spec), "--format", "json", "--jobs", "1"],
        capture_output=True,
        text=True,
    )
    (cli,) = json.loads(out.stdout)["results"]
    cli.pop("index")
    assert ravel.verify(spec, jobs=1).json == cli


# --- controllers as bytes ---------------------------------------------------


def test_a_model_file_read_into_bytes_gives_the_same_result():
    by_path = ravel.verify(DI)
    data = DI_MODEL.read_bytes()
    for given in (data, bytearray(data), memoryview(data)):
        r = ravel.verify(DI, controller=given)
        assert r.verdict == by_path.verdict
        assert np.array_equal(r.lower, by_path.lower) and np.array_equal(r.upper, by_path.upper)
        assert r["controller"]["sha256"] == by_path["controller"]["sha256"]


def test_a_network_built_with_onnx_helper_round_trips():
    # the shipped model's weights, exported again from NumPy by onnx.helper
    model = mlp_onnx_bytes(layers_of(DI_MODEL))
    again = ravel.verify(DI, controller=model)
    assert again.verdict == "VERIFIED"
    assert np.array_equal(again.lower, ravel.verify(DI).lower)
    # weights that steer the other way are not verified
    flipped = [(w, b) for w, b in layers_of(DI_MODEL)]
    flipped[-1] = (-flipped[-1][0], -flipped[-1][1])
    assert ravel.verify(DI, controller=mlp_onnx_bytes(flipped)).verdict != "VERIFIED"


def test_a_controller_path_overrides_the_specs():
    r = ravel.verify(text=DI.read_text(), directory=SPECS, controller=DI_MODEL)
    assert r.verdict == "VERIFIED"


def test_model_bytes_have_no_external_data():
    data = (MODELS / "double_integrator_external.onnx").read_bytes()
    with pytest.raises(ravel.RavelError) as e:
        ravel.verify(DI, controller=data)
    assert e.value.code is not None
    assert "bytes" in str(e.value)
    # the same model by path reads its external data beside it
    assert ravel.verify(DI, controller=MODELS / "double_integrator_external.onnx").verdict == "VERIFIED"


# --- hostile inputs ---------------------------------------------------------


@pytest.mark.parametrize(
    "data",
    [
        b"",
        DI_MODEL.read_bytes()[: len(DI_MODEL.read_bytes()) // 2],
        b"\x00" * 64,
        b"\xff" * 1000,
        bytes(range(256)) * 16,
    ],
    ids=["empty", "truncated", "zeros", "ones", "noise"],
)
def test_bad_model_bytes_are_diagnostics(data):
    with pytest.raises(ravel.RavelError) as e:
        ravel.verify(DI, controller=data)
    assert e.value.code is not None and e.value.code.startswith("E")


def test_model_bytes_over_the_size_limit_are_refused_before_any_copy():
    huge = bytes(ravel.MAX_CONTROLLER_BYTES + 1)
    with pytest.raises(ravel.RavelError) as e:
        ravel.check(DI, controller=huge)
    assert "limit" in str(e.value)
    del huge


def test_a_model_declaring_a_huge_tensor_is_refused():
    model = onnx.load(str(DI_MODEL))
    w = model.graph.initializer[0]
    del w.dims[:]
    w.dims.extend([1 << 31, 1 << 31])
    with pytest.raises(ravel.RavelError):
        ravel.verify(DI, controller=model.SerializeToString())


def test_nan_weights_are_refused():
    layers = layers_of(DI_MODEL)
    layers[0][0][0, 0] = np.nan
    with pytest.raises(ravel.RavelError) as e:
        ravel.verify(DI, controller=mlp_onnx_bytes(layers))
    assert e.value.code == "E0306" and "NaN" in e.value.message


@pytest.mark.parametrize("limit", [float("nan"), float("inf"), -1.0])
def test_bad_time_limits_are_refused(limit):
    with pytest.raises(ravel.RavelError):
        ravel.verify(DI, time_limit=limit)


@pytest.mark.parametrize("jobs", [0, -3, 1.5, True])
def test_bad_jobs_are_refused(jobs):
    with pytest.raises((ravel.RavelError, OverflowError, TypeError)):
        ravel.verify(DI, jobs=jobs)


def test_a_spec_text_over_the_limit_is_refused():
    with pytest.raises(ravel.RavelError) as e:
        ravel.check(text="/" * (ravel.MAX_SPEC_BYTES + 1))
    assert "limit" in str(e.value)


def test_a_spec_that_is_not_utf8_is_refused(tmp_path):
    f = tmp_path / "bad.ravel"
    f.write_bytes(b"system \xff\xfe {}")
    with pytest.raises(ravel.RavelError) as e:
        ravel.check(f)
    assert "UTF-8" in str(e.value)


# --- certify ----------------------------------------------------------------


def test_a_certificate_checks_valid():
    r = ravel.verify(DI, certificate=True)
    assert r.certificate["format"].startswith("ravel-certificate")
    answer = ravel.certify(r.certificate, spec=DI, controller=DI_MODEL)
    assert answer["answer"] == "VALID", answer
    assert answer["reason"] is None and answer["cells"] >= 1 and answer["spec_text_differs"] is False


def test_a_certificate_file_with_recorded_paths_and_controller_bytes(tmp_path):
    r = ravel.verify(DI.resolve(), controller=DI_MODEL.resolve(), certificate=True)
    cert = tmp_path / "di.cert.json"
    cert.write_text(json.dumps(r.certificate))
    assert ravel.certify(cert)["answer"] == "VALID"
    assert ravel.certify(cert, controller=DI_MODEL.read_bytes())["answer"] == "VALID"
    assert ravel.certify(json.dumps(r.certificate).encode(), spec=DI, controller=DI_MODEL)["answer"] == "VALID"


def test_a_forged_certificate_is_rejected():
    r = ravel.verify(DI, certificate=True)
    forged = json.loads(json.dumps(r.certificate))
    forged["problem"]["horizon"] = forged["problem"].get("horizon", 5) + 1
    assert ravel.certify(forged, spec=DI, controller=DI_MODEL)["answer"] != "VALID"
    other = mlp_onnx_bytes(layers_of(MODELS / "double_integrator.onnx")[:-1] + [(np.ones((1, 5)), np.zeros(1))])
    with_other = ravel.certify(r.certificate, spec=DI, controller=other)
    assert with_other["answer"] == "INVALID" and "controller" in with_other["reason"]


def test_a_certificate_with_shrunk_claims_is_invalid():
    r = ravel.verify(DI, certificate=True)
    text = json.dumps(r.certificate)
    cert = json.loads(text)
    changed = 0

    def shrink(v):
        nonlocal changed
        if isinstance(v, dict):
            for k, x in v.items():
                if k == "hi" and isinstance(x, list) and x and all(isinstance(y, (int, float)) for y in x):
                    v[k] = [y - 0.5 for y in x]
                    changed += 1
                else:
                    shrink(x)
        elif isinstance(v, list):
            for x in v:
                shrink(x)

    shrink({k: v for k, v in cert.items() if k != "problem"})
    assert changed > 0
    assert ravel.certify(cert, spec=DI, controller=DI_MODEL)["answer"] != "VALID"


def test_junk_certificates_are_unreadable():
    for junk in (b"", b"not json", b"[]", b"{}"):
        answer = ravel.certify(junk, spec=DI, controller=DI_MODEL)
        assert answer["answer"] in ("UNREADABLE", "INVALID"), junk
        assert answer["answer"] != "VALID"


# --- the GIL ----------------------------------------------------------------


# the double integrator on 256 cells with many samples: a verify long
# enough for a waiting thread to wake up many times over
LONG = (
    DI.read_text()
    .replace("partitioner none", "partitioner uniform [16, 16]")
    .replace("samples     2000", "samples     100000")
)


def test_the_gil_is_released_during_verify():
    # With a switch interval far longer than the test, a thread holding the
    # GIL is never made to give it up: the counter can run only when verify
    # releases it (the counter gives it back itself, at every wait).
    count = 0
    go, stop = threading.Event(), threading.Event()

    def counter():
        nonlocal count
        go.wait()
        while not stop.is_set():
            count += 1
            stop.wait(0.0005)

    old = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)
    t = threading.Thread(target=counter)
    t.start()
    try:
        go.set()
        ravel.verify(text=LONG, directory=SPECS, jobs=1)
        during = count
    finally:
        stop.set()
        t.join()
        sys.setswitchinterval(old)
    assert during > 0


# --- the example ------------------------------------------------------------


def test_the_training_example_stops_when_verified():
    out = subprocess.run(
        [sys.executable, str(EXAMPLE)], capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "VERIFIED" in out.stdout and "certificate: VALID" in out.stdout
