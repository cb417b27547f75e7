"""BLAS runs one thread during benchlab's fits whatever was imported or set first; `import benchlab` stays light."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

FIT_WITH_NUMPY_FIRST = """
import json, sys
import numpy, scipy, scipy.linalg  # both OpenBLAS builds loaded before benchlab, with their own threads
import threadpoolctl
from benchlab.runfile import load_run

def blas_threads():
    return max(i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas")

import benchlab.identify.fit  # the module, not the function the package exports under that name
from benchlab.identify.data import prepare
from benchlab.model.catalog import model_spec
fit_module = sys.modules["benchlab.identify.fit"]
seen = []
residual_vector = fit_module.residual_vector

def spy(*args, **kwargs):  # called at every evaluation of the fit
    if len(seen) < 3:
        seen.append(blas_threads())
    return residual_vector(*args, **kwargs)

fit_module.residual_vector = spy
before = blas_threads()
fit_module.fit(model_spec("linear"), [prepare(load_run(sys.argv[1]))], max_nfev=2)
print(json.dumps({"before": before, "during": seen, "after": blas_threads()}))
"""


def _clean_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    return env | extra


@pytest.mark.parametrize("env, threads_before", [
    ({}, None),                                # the order with nothing set: BLAS has its default threads
    ({"OPENBLAS_NUM_THREADS": "2"}, 2),        # a caller's own setting: kept outside the fit, not inside it
])
def test_fit_runs_single_threaded_blas_when_numpy_and_scipy_came_first(run_file, env, threads_before) -> None:
    out = subprocess.run([sys.executable, "-c", FIT_WITH_NUMPY_FIRST, str(run_file)], env=_clean_env(**env),
                         capture_output=True, text=True, check=True).stdout
    seen = json.loads(out.splitlines()[-1])
    assert seen["during"] and set(seen["during"]) == {1}
    if threads_before is not None:  # OpenBLAS runs no more threads than the process has cores
        assert seen["before"] == seen["after"] == min(threads_before, len(os.sched_getaffinity(0)))


def test_import_benchlab_errors_is_light() -> None:
    code = ("import sys, benchlab.errors, benchlab; "
            "print(sorted(m for m in ('pandas', 'h5py', 'numba', 'numpy', 'scipy') if m in sys.modules)); "
            "print(hasattr(benchlab, 'os'))")
    heavy, has_os = subprocess.run([sys.executable, "-c", code], env=_clean_env(), capture_output=True, text=True,
                                   check=True).stdout.split("\n")[:2]
    assert heavy == "[]" and has_os == "False"


def test_api_names_load_on_first_use() -> None:
    code = ("import sys, benchlab; from benchlab import simulate; "
            "print(callable(benchlab.load_run), callable(benchlab.load_params), 'pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], env=_clean_env(), capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["True", "True", "True"]
    with pytest.raises(AttributeError):
        import benchlab
        benchlab.no_such_name  # noqa: B018


#: What a `benchlab` process must not load before its command runs (issue 17: 3.3-3.8 s of CPU for `--help`).
HEAVY = ("scipy", "pandas", "matplotlib", "h5py", "numba", "can", "asammdf", "dask")
LOADED_HEAVY = f"print(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r})))"


@pytest.mark.parametrize("argv", [["--help"], ["watch", "--help"], ["probe", "--help"]])
def test_cli_help_imports_no_heavy_library(argv) -> None:
    code = ("import sys, runpy\n"
            f"sys.argv = ['benchlab', *{argv!r}]\n"
            "try:\n    runpy.run_module('benchlab.cli', run_name='__main__')\n"  # as `python -m benchlab.cli`
            "except SystemExit as exc:\n    assert exc.code == 0, exc.code\n"
            f"{LOADED_HEAVY}\n")
    out = subprocess.run([sys.executable, "-c", code], env=_clean_env(), capture_output=True, text=True,
                         check=True).stdout.splitlines()
    assert out[0].startswith("usage: benchlab") and out[-1] == "[]"


def test_building_the_parser_imports_no_heavy_library() -> None:
    code = ("import sys\nfrom benchlab.cli import build_parser\n"
            "print(build_parser().parse_args(['watch', 'run.h5']).handler.__module__)\n"
            f"{LOADED_HEAVY}\n")
    module, heavy = subprocess.run([sys.executable, "-c", code], env=_clean_env(), capture_output=True, text=True,
                                   check=True).stdout.splitlines()[:2]
    assert module == "benchlab.commands.watch" and heavy == "[]"


#: A command line run as the `benchlab` console script runs it, then the exit code and whether pandas and pyarrow
#: were loaded (issue 47: pandas loads pyarrow whenever it is installed, though only Parquet needs it).
AS_CONSOLE = ("import sys\nfrom benchlab.console import main\n"
              "sys.argv = ['benchlab', *sys.argv[1:]]\ncode = main()\n"
              "print(code, 'pandas' in sys.modules, any(m.split('.')[0] == 'pyarrow' for m in sys.modules))")


def _as_console(*argv: object, code: int = 0) -> list[str]:
    done = subprocess.run([sys.executable, "-c", AS_CONSOLE, *map(str, argv)], env=_clean_env(), capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    printed = done.stdout.splitlines()[-1].split()
    assert printed[0] == str(code), done.stderr[-2000:]
    return printed[1:]


@pytest.mark.parametrize("command", ["run", "simulate", "identify", "diagnose"])
def test_commands_without_parquet_load_no_pyarrow(command, run_file, params_file, tmp_path) -> None:
    """Each command does its work on pandas without pyarrow loaded; `export --to OUT.parquet` has it. diagnose is
    asked for a run too short to diagnose: refused (exit 2) after its implementation is imported and the run loaded,
    not after the ≈ 20 s of a diagnosis (the main job runs one through the console script)."""
    argv, code = {"run": (["run", "table1", "--bench", "sim", "--duration", "120", "--out", tmp_path / "r.h5", "-q"], 0),
                  "simulate": (["simulate", run_file, "--params", params_file, "--out", tmp_path / "sim.h5"], 0),
                  "identify": (["identify", run_file, "--model", "linear", "--out", tmp_path / "fit.json", "-q"], 0),
                  "diagnose": (["diagnose", run_file, "--json", "-q"], 2)}[command]
    assert _as_console(*argv, code=code) == ["True", "False"]  # pandas loaded, pyarrow not


def test_a_csv_export_loads_neither_pyarrow_nor_the_simulation_stack(run_file, tmp_path) -> None:
    """Issue 47: a command that does not simulate loads no numba or scipy, and only Parquet loads pyarrow."""
    code = ("import sys\nfrom benchlab.console import main\nsys.argv = ['benchlab', *sys.argv[1:]]\ncode = main()\n"
            "print(code, sorted(m for m in ('pandas', 'pyarrow', 'numba', 'scipy') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code, "export", str(run_file), "--to", str(tmp_path / "run.csv")],
                          env=_clean_env(), capture_output=True, text=True, timeout=600)
    assert done.stdout.splitlines()[-1] == "0 ['pandas']", done.stderr[-2000:]


def test_parquet_export_loads_pyarrow(run_file, tmp_path) -> None:
    assert _as_console("export", run_file, "--to", tmp_path / "run.parquet") == ["True", "True"]


def test_numba_finds_a_blas_without_the_scipy_linalg_package() -> None:
    """Issue 47: numba's first kernel load checks for a BLAS by importing scipy.linalg.cython_blas, which ran the
    whole scipy.linalg package (0.2 s of a command that simulates). benchlab.jit loads that module alone: a BLAS
    kernel still computes, scipy.linalg stays unloaded, and a later import of it takes the module as its own."""
    code = ("import sys\nimport numpy as np\nfrom benchlab.jit import njit\n"
            "@njit\ndef product(a):\n    return np.dot(a, a)\n"
            "a = np.arange(9.0).reshape(3, 3)\nsame = np.array_equal(product(a), a @ a)\n"
            "loaded = 'scipy.linalg' in sys.modules\nimport scipy.linalg.cython_blas\n"
            "print(same, loaded, scipy.linalg.cython_blas is sys.modules['scipy.linalg.cython_blas'])")
    out = subprocess.run([sys.executable, "-c", code], env=_clean_env(), capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "False", "True"]
