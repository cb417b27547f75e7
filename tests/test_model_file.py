"""Model files (contract section 6): the clutch files are the paper's eq. (6)-(11), the expression parser never
executes anything, a model file and a parameter file with "network" round-trip, bad model files exit 2."""

from __future__ import annotations

import json
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchlab.cli import main
from benchlab.identify.data import prepare
from benchlab.identify.fit import fit
from benchlab.identify.spec import ModelSpec
from benchlab.model.build import build_network
from benchlab.model.catalog import BUILTIN, builtin, model_spec
from benchlab.model.definition import load_model, parse_model, to_toml
from benchlab.model.expressions import ExpressionError, affine_parts, compile_expression, parse
from benchlab.model.params import check_params, load_params, paper_params, save_params
from benchlab.runfile import write_run
from benchlab.network.simulation import simulate
from benchlab.network.solver import run_network

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from python_clutch import python_clutch  # noqa: E402 - eq. (6)-(11) in Python, independent of the model files


@pytest.mark.parametrize("model", ["linear", "nonlinear"])
def test_clutch_files_simulate_the_papers_equations(short_run, model):
    params = paper_params(model)
    by_file = simulate(short_run, params)
    by_hand = simulate(short_run, params, python_clutch(model == "nonlinear"))
    assert list(by_file.columns) == ["T_pressure_plate", "T_flywheel", "T_air", "T_housing"]
    np.testing.assert_allclose(by_file.to_numpy(), by_hand.to_numpy(), rtol=0, atol=1e-9)
    assert np.ptp(by_file["T_flywheel"].to_numpy()) > 5.0  # the run heats the clutch: the comparison has content


@pytest.mark.parametrize("model", ["linear", "nonlinear"])
def test_clutch_files_identify_the_same_parameters_as_the_papers_equations(short_run, model):
    data = [prepare(short_run, 1.0)]
    spec = model_spec(model)
    by_file = fit(spec, data, max_nfev=40)
    by_hand = fit(ModelSpec(model, python_clutch(model == "nonlinear"), spec.free, spec.fixed), data, max_nfev=40)
    for name in by_file.free_names:
        assert by_file.params[name] == pytest.approx(by_hand.params[name], rel=1e-3), name


def test_builtin_names_are_the_model_files():
    for name, path in BUILTIN.items():
        assert path.parent.name == "models" and path.name == f"clutch-{name}.toml"
        assert builtin(name).label == name and builtin(name) == load_model(path)
    assert [p.name for p in model_spec("linear").free] == ["C_P", "C_F", "C_A", "C_T", "R_AT", "R_Feng", "R_Tamb", "R0"]
    assert [p.name for p in model_spec("nonlinear").free][-4:] == ["a1", "b1", "a2", "b2"]


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_toml_and_json_round_trips(name):
    model = builtin(name)
    assert parse_model(tomllib.loads(to_toml(model)), "again.toml") == model
    assert parse_model(json.loads(json.dumps(model.to_doc())), "again.json") == model


def test_parameter_file_carries_the_network(tmp_path, short_run):
    model = parse_model({**builtin("nonlinear").to_doc(), "name": "my-clutch"}, "my.toml")
    save_params(tmp_path / "p.json", check_params(model, paper_params("nonlinear")))
    params = load_params(tmp_path / "p.json")
    assert params.model == "my-clutch" and params.definition == model
    np.testing.assert_allclose(simulate(short_run, params).to_numpy(),
                               simulate(short_run, paper_params("nonlinear")).to_numpy(), rtol=0, atol=1e-12)
    doc = json.loads((tmp_path / "p.json").read_text())
    assert doc["network"]["schema"] == "benchlab-model/1" and doc["model"] == "my-clutch"
    builtin_doc = tmp_path / "b.json"
    save_params(builtin_doc, paper_params("linear"))
    assert "network" not in json.loads(builtin_doc.read_text())  # section 2 files stay as they were


def test_affine_source_enters_the_state_matrix_exactly():
    """dT/dt = (q0 + k·T)/C with k > 0 (copper loss rising with temperature): T(t) = (T0 + q0/k)·e^(k t / C) − q0/k."""
    model = parse_model({"schema": "benchlab-model/1", "nodes": {"W": "C"}, "outputs": {"T_w": "W"},
                         "sources": [{"name": "copper", "node": "W", "heat": "I*I*R20*(1 + alpha*(W - 20))"}],
                         "parameters": {"C": {"start": 100.0, "min": 1.0, "max": 1e4},
                                        "R20": {"start": 0.5, "min": 0.01, "max": 10.0},
                                        "alpha": {"start": 0.004, "min": 0.0, "max": 0.01}}}, "w.toml")
    network = build_network(model)
    p = {"C": 100.0, "R20": 0.5, "alpha": 0.004}
    n, dt, current = 500, 2.0, 3.0
    states = run_network(network, p, {"I": np.full(n, current)}, dt, np.array([25.0]))
    k = current ** 2 * p["R20"] * p["alpha"]
    q0 = current ** 2 * p["R20"] * (1 - 20 * p["alpha"])
    t = np.arange(n + 1) * dt
    np.testing.assert_allclose(states[:, 0], (25.0 + q0 / k) * np.exp(k * t / p["C"]) - q0 / k, rtol=1e-10)


@pytest.mark.parametrize("text,nodes,expected", [
    ("3*W + 2", {"W"}, {"W": 3.0, None: 2.0}),
    ("-(W - 20) / 4", {"W"}, {"W": -0.25, None: 5.0}),
    ("where(x > 1, 2*W, W + 1)", {"W"}, {"W": 1.5, None: 0.5}),  # x = [0, 2]: coefficients averaged below
    ("k*(W - S)", {"W", "S"}, {"W": 2.0, "S": -2.0, None: 0.0}),
])
def test_affine_parts(text, nodes, expected):
    expr = parse(text)
    kinds = {n: "node" if n in nodes else "parameter" if n == "k" else "channel" for n in expr.names}
    constant, coefficients = affine_parts(expr, kinds)
    values = ({"k": 2.0}, {"x": np.array([0.0, 2.0])}, {})
    assert set(coefficients) == {k for k in expected if k is not None}
    for node, want in expected.items():
        got = constant(*values) if node is None else coefficients[node](*values)
        assert float(np.mean(got)) == pytest.approx(want)


@pytest.mark.parametrize("text", ["W*W", "exp(W)", "1/W", "W**2", "where(W > 20, 1, 0)", "maximum(W, 0)", "x*W*S"])
def test_non_affine_temperature_terms_are_refused(text):
    expr = parse(text)
    kinds = {n: "node" if n in ("W", "S") else "channel" for n in expr.names}
    with pytest.raises(ExpressionError):
        affine_parts(expr, kinds)


MALICIOUS = ["__import__('os').system('touch PWNED')", "x.__class__", "open('f')", "(lambda: 1)()", "[1, 2]",
             "x if y else z", "eval('1')", "exp(x, y)", "exp(x=1)", "'text'", "True", "a < b < c", "x[0]",
             "f'{x}'", "exp(*x)", "1; 2", "x := 1", "not x", "x and y", "x @ y", "x // 2", "x % 2", "~x", "x << 1",
             "__builtins__", "(x for x in y)", "{1: 2}", "None", "1j"]


@pytest.mark.parametrize("text", MALICIOUS)
def test_python_in_an_expression_is_refused(text, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ExpressionError):
        parse(text)
    assert not (tmp_path / "PWNED").exists()


TOKENS = st.sampled_from(["x", "y", "k", "W", "1", "2.5", "1e308", "0", "-", "+", "*", "/", "**", "(", ")", ",",
                          "<", ">=", "==", "exp", "log", "sqrt", "abs", "minimum", "maximum", "where", "__import__",
                          ".", "os", "system", "[", "]", "lambda", ":", "'", "if", "else", " "])


def _evaluate_if_valid(text: str) -> None:
    try:
        expr = parse(text)
    except ExpressionError:
        return
    kinds = {n: "parameter" if n == "k" else "node" if n == "W" else "channel" for n in expr.names}
    values = ({"k": -1.5}, {n: np.array([-2.0, 0.0, 3.0]) for n in expr.names}, {"W": np.array([20.0, 21.0, 22.0])})
    with np.errstate(all="ignore"):
        result = np.asarray(compile_expression(expr, kinds)(*values))
    assert result.dtype.kind in "fb"  # numbers, never objects, strings or complex values
    try:
        affine_parts(expr, kinds)
    except ExpressionError:
        pass


@settings(max_examples=400, deadline=None)
@given(st.lists(TOKENS, max_size=30).map("".join))
def test_fuzzed_token_soup_never_crashes_or_executes(text):
    _evaluate_if_valid(text)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=60))
def test_fuzzed_text_never_crashes(text):
    _evaluate_if_valid(text)


def _model_doc() -> dict:
    return tomllib.loads(to_toml(builtin("nonlinear")))


def _set(path, value):
    def edit(doc):
        *keys, last = path
        target = doc
        for key in keys:
            target = target[key]
        target[last] = value
    return edit


BAD_MODELS = {
    "syntax error": (_set(("links", 0, "resistance"), "a1 * (exp(b1"), "links[R_PA].resistance"),
    "attribute access": (_set(("links", 0, "resistance"), "R0.__class__"), "links[R_PA].resistance"),
    "import": (_set(("sources", 0, "heat"), "__import__('os').getcwd()"), "sources[plate share].heat"),
    "call outside the list": (_set(("sources", 0, "heat"), "print(friction_power)"), "sources[plate share].heat"),
    "link to nothing": (_set(("links", 2, "between"), ["A", "X"]), "links[R_AT].between"),
    "output to no state": (_set(("outputs", "T_air"), "Q"), "outputs.T_air"),
    "non-affine temperature": (_set(("sources", 0, "heat"), "P*P*0.001"), "sources[plate share].heat"),
    "no bounds": (lambda d: d["parameters"]["R0"].pop("max"), "parameters.R0.max"),
    "min above max": (_set(("parameters", "R0", "min"), 60.0), "parameters.R0"),
    "node without capacity": (_set(("nodes", "A"), "C_X"), "nodes.A"),
    "temperature in a resistance": (_set(("links", 2, "resistance"), "R_AT*(1 + 0.01*A)"), "links[R_AT].resistance"),
    "unknown key": (_set(("links", 2, "resistence"), "R_AT"), "links[R_AT].resistence"),
    "wrong schema": (_set(("schema",), "benchlab-model/9"), "schema"),
    "name collision": (_set(("nodes", "R0"), "C_A"), "nodes.R0"),
    "calibration of no output": (lambda d: d.update(calibrations=[{"output": "T_plate", "offset": "R0"}]),
                                 "calibrations[0].output"),
    "calibration gain that may be zero": (lambda d: d.update(calibrations=[{"output": "T_air", "gain": "b1"}]),
                                          "parameters.b1.min"),
}


@pytest.mark.parametrize("case", sorted(BAD_MODELS))
def test_bad_model_file_exits_2_with_one_line(case, tmp_path, run_file, capsys):
    edit, entry = BAD_MODELS[case]
    doc = _model_doc()
    edit(doc)
    path = tmp_path / "bad.toml"
    path.write_text(to_toml_doc(doc))
    code = main(["identify", str(run_file), "--model", str(path), "--out", str(tmp_path / "p.json")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and str(path) in err and entry in err, err


def to_toml_doc(doc: dict) -> str:
    """A TOML text of a model document that may be invalid as a model (so not through parse_model)."""
    lines = []

    def value(v):
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)
    for k, v in doc.items():
        if not isinstance(v, (dict, list)) or (isinstance(v, list) and not any(isinstance(x, dict) for x in v)):
            lines.append(f"{k} = {value(v)}")
    for k, v in doc.items():
        if isinstance(v, dict):
            flat = {a: b for a, b in v.items() if not isinstance(b, dict)}
            lines += [f"[{k}]"] + [f"{a} = {value(b)}" for a, b in flat.items()]
            for a, b in v.items():
                if isinstance(b, dict):
                    lines += [f"[{k}.{a}]"] + [f"{x} = {value(y)}" for x, y in b.items()]
        elif isinstance(v, list) and any(isinstance(x, dict) for x in v):
            for item in v:
                lines += [f"[[{k}]]"] + [f"{a} = {value(b)}" for a, b in item.items()]
    return "\n".join(lines) + "\n"


def test_model_file_syntax_error_and_missing_file(tmp_path, run_file, capsys):
    bad = tmp_path / "broken.toml"
    bad.write_text("schema = \n")
    assert main(["identify", str(run_file), "--model", str(bad), "--out", str(tmp_path / "p.json")]) == 2
    assert "broken.toml: file: TOML" in capsys.readouterr().err
    assert main(["identify", str(run_file), "--model", str(tmp_path / "none.toml"), "--out", "p.json"]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["identify", str(run_file), "--model", "quadratic", "--out", "p.json"]) == 2
    assert "--model: quadratic" in capsys.readouterr().err


def test_run_without_a_channel_the_model_reads_is_bad_input(tmp_path, short_run, capsys):
    path = tmp_path / "r.h5"
    write_run(path, short_run.drop(columns=["engine_speed"]).iloc[:2000], short_run.attrs["dt"], protocol="table1")
    model = tmp_path / "m.toml"
    model.write_text(to_toml(parse_model({**builtin("nonlinear").to_doc(), "requires": []}, "m.toml")))
    assert main(["identify", str(path), "--model", str(model), "--out", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err
    assert "/aligned/engine_speed" in err and "clutch-nonlinear" in err


def test_cooldown_refuses_parameters_of_a_model_that_is_not_the_clutch(tmp_path, run_file, capsys):
    model = parse_model({"schema": "benchlab-model/1", "name": "one-node", "nodes": {"W": "C"}, "outputs": {"T_air": "W"},
                         "parameters": {"C": {"start": 100.0, "min": 1.0, "max": 1e4}}}, "one.toml")
    save_params(tmp_path / "one.json", check_params(model, {"C": 200.0}))
    assert main(["cooldown", str(run_file), "--params", str(tmp_path / "one.json"), "--no-store"]) == 2
    err = capsys.readouterr().err
    assert "one.json: params.C_P" in err and len(err.strip().splitlines()) == 1


def test_a_run_channel_named_like_a_parameter_is_the_runs_fault_unless_the_contract_named_it(short_run):
    """Issue 44: a channel an import's mapping added under a parameter's name (C_P) made diagnose blame the
    built-in model file. The run's channel is named as the fault; a model whose parameter takes a contract
    channel's name (load_torque) is the model file's."""
    from benchlab.errors import InputError
    from benchlab.model.runs import check_run

    model = builtin("linear")
    run = short_run.iloc[:200].copy()
    run.attrs = {"source": "imported.h5"}
    run["C_P"] = 1.0
    with pytest.raises(InputError, match=r"^imported\.h5: /aligned/C_P: a channel name other than a parameter"):
        check_run(model, run)
    text = Path(model.source).read_text().replace("C_A", "load_torque")
    renamed = parse_model(tomllib.loads(text), "renamed.toml")
    with pytest.raises(InputError, match=r"^renamed\.toml: parameters\.load_torque: a name no channel"):
        check_run(renamed, short_run.iloc[:200])
