"""The software-in-the-loop proof: the generated module compiled with the machine's `cc`, run over a run file sample
by sample (a shared object with a small driver loop, called through ctypes), and compared with benchlab's own online
observer and wear (`benchlab.observer.online.OnlineObserver`) fed the same samples. docs/deploy.md."""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from benchlab.deploy.plan import Plan
from benchlab.errors import InputError
from benchlab.network.simulation import initial_state, input_channels
from benchlab.observer.batch import fresh, sensor_readings
from benchlab.observer.online import OnlineObserver

#: The flags the module is proven with (the issue's, and the tests').
STRICT = ("-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wdouble-promotion", "-Werror")
OPTIMISE = ("-O2",)
WEAR_KEYS = ("wear_plate_mm", "wear_flywheel_mm")


def compiler() -> str:
    """The machine's C compiler (`cc`); InputError in one line where there is none."""
    found = shutil.which("cc")
    if found is None:
        raise InputError("cc", "C compiler", "a C compiler on PATH to verify the module (install gcc or clang)")
    return found


def _run(command: list[str], cwd: Path) -> str:
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed: {(done.stderr or done.stdout).strip()[:2000]}")
    return done.stdout


def driver(plan: Plan) -> str:
    """C of the driver: the module's step over a whole run, one call per sample, and the state's size."""
    p = plan.name
    wear = plan.clutch is not None
    return "\n".join([
        f'#include "{p}.h"', "#include <stddef.h>", "#include <math.h>", "",
        f"size_t {p}_state_bytes(void);", f"size_t {p}_state_bytes(void) {{ return sizeof({p}_state); }}",
        f"void {p}_run(long samples, const {p}_real *inputs, const {p}_real *readings, const {p}_real *start, "
        f"{p}_real *temperature, {p}_real *std, {p}_real *wear);",
        f"void {p}_run(long samples, const {p}_real *inputs, const {p}_real *readings, const {p}_real *start, "
        f"{p}_real *temperature, {p}_real *std, {p}_real *wear)", "{",
        f"    {p}_state state;", f"    {p}_estimate out;", "    long k;", "    int i;",
        f"    {p}_init(&state, start);", "    for (k = 0; k < samples; ++k) {",
        f"        {p}_step(&state, inputs + k * {p.upper()}_INPUTS, readings + k * {p.upper()}_SENSORS, &out);",
        f"        for (i = 0; i < {p.upper()}_STATES; ++i) {{",
        f"            temperature[k * {p.upper()}_STATES + i] = out.temperature[i];",
        f"            std[k * {p.upper()}_STATES + i] = out.std[i];", "        }",
        *([f"        for (i = 0; i < 2; ++i) {{ wear[k * 4 + i] = out.wear_mm[i]; wear[k * 4 + 2 + i] = out.energy_J[i]; }}"]
          if wear else ["        (void)wear;"]),
        "    }", "}", ""])


@dataclass(frozen=True)
class Built:
    """The module compiled: the shared object with the driver, and the module's own object's size."""

    library: Path
    code_bytes: int


def build(directory: Path, plan: Plan) -> Built:
    """Compile `<name>.c` with the strict flags into an object (its `size` is the code budget) and, with the driver,
    into a shared object."""
    cc = compiler()
    p = plan.name
    (directory / f"{p}_driver.c").write_text(driver(plan))
    _run([cc, *STRICT, *OPTIMISE, "-c", f"{p}.c", "-o", f"{p}.o"], directory)
    _run([cc, *STRICT, *OPTIMISE, "-fPIC", "-shared", f"{p}.c", f"{p}_driver.c", "-o", f"lib{p}_sil.so", "-lm"],
         directory)
    return Built(directory / f"lib{p}_sil.so", code_bytes(directory / f"{p}.o"))


def code_bytes(obj: Path) -> int:
    """text + data + bss of an object, as `size` reports them (Berkeley format's `dec`)."""
    size = shutil.which("size")
    if size is None:
        return int(obj.stat().st_size)
    line = _run([size, obj.name], obj.parent).strip().splitlines()[-1].split()
    return int(line[3])


def run_inputs(plan: Plan, run: pd.DataFrame) -> tuple[np.ndarray, dict[str, np.ndarray], tuple[str, ...]]:
    """(N, inputs) of the module from a run (drop-outs held, a boundary from the first of its channels the run
    holds), the run's channels, and the Python observer's input names for the same columns."""
    channels = input_channels(run)
    source = run.attrs.get("source", "<run>")
    columns, names = [], []
    for name, candidates in zip(plan.inputs, plan.input_sources):
        chosen = next((c for c in candidates if c in channels), None)
        if chosen is None:
            raise InputError(source, f"/aligned/{name}", "a channel the module reads (the run has none)")
        columns.append(channels[chosen])
        names.append(chosen)
    return np.column_stack(columns) if columns else np.zeros((len(run), 0)), channels, tuple(names)


def reference(plan: Plan, run: pd.DataFrame) -> dict[str, np.ndarray]:
    """benchlab's online observer with its wear over the run: temperatures, their σ, wear per side (N, ...)."""
    inputs, channels, names = run_inputs(plan, run)
    readings = fresh(sensor_readings(run, plan.sensors))
    x0 = initial_state(plan.params.network, channels, run.attrs.get("source", "<run>"), params=plan.params)
    unique = list(dict.fromkeys(names))
    columns = [names.index(c) for c in unique]
    observer = OnlineObserver(plan.params, plan.sensors, unique, x0, plan.dt, plan.params.network, plan.noise,
                              plan.clutch)
    n, count = len(run), plan.n
    temperature, std, wear = np.empty((n, count)), np.empty((n, count)), np.full((n, 2), np.nan)
    rows = inputs[:, columns].tolist()
    for k in range(n):
        estimate = observer.step(rows[k], readings[k])
        temperature[k], std[k] = estimate.temperature, estimate.std
        if estimate.wear is not None:
            wear[k] = estimate.wear[:2]
    return {"temperature": temperature, "std": std, "wear": wear, "x0": x0}


def run_module(built: Built, plan: Plan, run: pd.DataFrame, x0: np.ndarray, real: str,
               inputs: np.ndarray | None = None, readings: np.ndarray | None = None) -> dict[str, Any]:
    """The compiled module over the run (or over `inputs` and `readings` given as they are, drop-outs and all):
    temperatures, σ, wear and energy per side, state bytes, µs per step."""
    dtype = np.float32 if real == "float" else np.float64
    inputs = np.ascontiguousarray(run_inputs(plan, run)[0] if inputs is None else inputs, dtype=dtype)
    readings = np.ascontiguousarray(fresh(sensor_readings(run, plan.sensors)) if readings is None else readings,
                                    dtype=dtype)
    n = len(run)
    temperature, std, wear = (np.zeros((n, plan.n), dtype), np.zeros((n, plan.n), dtype), np.zeros((n, 4), dtype))
    library = ctypes.CDLL(str(built.library))
    pointer = np.ctypeslib.ndpointer(dtype=dtype, flags="C_CONTIGUOUS")
    step = getattr(library, f"{plan.name}_run")
    step.argtypes = [ctypes.c_long, pointer, pointer, pointer, pointer, pointer, pointer]
    step.restype = None
    size = getattr(library, f"{plan.name}_state_bytes")
    size.restype = ctypes.c_size_t
    start = np.ascontiguousarray(x0, dtype=dtype)
    began = time.perf_counter()
    step(n, inputs, readings if readings.size else np.zeros(1, dtype), start, temperature, std, wear)
    elapsed = time.perf_counter() - began
    return {"temperature": temperature.astype(np.float64), "std": std.astype(np.float64),
            "wear": wear[:, :2].astype(np.float64), "energy": wear[:, 2:].astype(np.float64),
            "state_bytes": int(size()), "step_us": 1e6 * elapsed / max(n, 1)}


def compare(plan: Plan, ours: Mapping[str, np.ndarray], theirs: Mapping[str, np.ndarray]) -> dict[str, Any]:
    """The largest deviations: per temperature (K), of every σ and of the wear (relative), the plate's named."""
    dev = {name: float(np.max(np.abs(ours["temperature"][:, i] - theirs["temperature"][:, i])))
           for i, name in enumerate(plan.state_channels)}
    sigma = {name: float(np.max(np.abs(ours["std"][:, i] / theirs["std"][:, i] - 1.0)))
             for i, name in enumerate(plan.state_channels)}
    wear_dev = None
    if plan.clutch is not None:
        final_theirs, final_ours = theirs["wear"][-1], ours["wear"][-1]
        wear_dev = float(np.max(np.abs(final_ours / np.where(final_theirs > 0, final_theirs, np.nan) - 1.0)))
        wear_dev = None if np.isnan(wear_dev) else wear_dev
    return {"max_abs_dev_K": dev, "sigma_rel_dev": sigma,
            "plate_sigma_rel_dev": sigma.get("T_pressure_plate", max(sigma.values()) if sigma else None),
            "wear_rel_dev": wear_dev}
