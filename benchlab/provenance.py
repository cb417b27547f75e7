"""Which bench produced a run, in words: the one phrase summaries and pages use for the run file's `bench` attribute
("sim", a hardware bench's BENCH.toml, "imported"), so no page leaves a reader to guess whether the data is real."""

from __future__ import annotations

#: The run file's `bench` for benchlab's simulated bench (`benchlab run --bench sim`).
SIMULATED = "sim"
#: The run file's `bench` for a file `benchlab import` made (the bench is whoever measured the source file).
IMPORTED = "imported"


def bench_text(bench: "str | None", short: bool = False, simulated: str = "") -> str:
    """The bench as a reader should see it: simulated, imported, or the hardware bench's configuration file with
    the devices it simulated (`simulated`, the run file's `bench_simulated`, e.g. "node sim://rig, CAN sim://rig");
    `short` for a table cell."""
    if bench == SIMULATED:
        return "simulated (sim)" if short else "the simulated bench (--bench sim: emulated devices, a model plant)"
    if bench == IMPORTED:
        return "imported" if short else "an imported file (benchlab import: the bench that measured it is not recorded)"
    if not bench:
        return "not recorded" if short else "an unnamed bench (the run file has no bench attribute)"
    if simulated:
        return f"partly simulated: {bench}" if short else f"the hardware bench {bench} (simulated: {simulated})"
    return f"hardware: {bench}" if short else f"the hardware bench {bench}"
