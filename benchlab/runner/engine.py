"""Executes a protocol (a schedule of Steps) on a bench, acquiring everything, with interlocks that always hold.

The loop ticks on the shared clock (fast ticks while the clutch slips or a launch runs, slow ticks
otherwise): the bench's drivers are polled, their rows go to the run-file writer, the interlocks and the
step's end conditions are evaluated on the latest values, and set-points are sent. An interlock puts the
bench in its safe state at once (clutch open at zero torque, load torque zero, engine at idle) and is an
event; then the runner waits until the cause has cleared (plus `resume_after_s`) and continues with the
next cycle, or aborts, as the limits say. SIGINT/SIGTERM set a flag the loop checks every tick.
"""

from __future__ import annotations

import collections
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from benchlab.acquire import RunWriter
from benchlab.progress import Task
from benchlab.runfile.schema import END_CONDITION, END_SYNCHRONISED, END_TIME
from benchlab.runner.clock import Clock
from benchlab.runner.devices import BenchStatus
from benchlab.runner.interlocks import Engagements, InterlockSet, Trip
from protocols.limits import BenchLimits
from protocols.safety import FRICTION_POWER_SEEN_W, OPEN_IDLE, SafeState, strongest
from protocols.schedule import Condition, Step, pulse_due, setpoints

STATE_FIELDS = ("cycle", "next_step", "resumes", "energy_j", "held")  # held: 1 while an interlock holds the bench


class Bench(Protocol):
    """What the runner needs from a bench (DriverBench implements it)."""

    status: BenchStatus
    gateway: Any

    def command(self, engine_rpm: float, clutch_torque_nm: float, clutch_open: bool, load_nm: float) -> None: ...
    def safe_state(self, state: SafeState = OPEN_IDLE) -> None: ...
    def poll(self) -> tuple[list, list]: ...


class Stopped(Exception):
    """A stop was requested (signal) or an interlock aborts the run."""

    def __init__(self, reason: str, code: int) -> None:
        super().__init__(reason)
        self.reason, self.code = reason, code


class _SkipCycle(Exception):
    pass


@dataclass
class RunSummary:
    cycles_planned: int
    cycles_done: int = 0
    energy_j: float = 0.0
    engagements: int = 0
    peak: dict[str, float] = field(default_factory=lambda: {"T_flywheel": -math.inf, "T_air": -math.inf})
    events: collections.Counter = field(default_factory=collections.Counter)
    frames_ok: int = 0
    frames_lost: int = 0
    status: str = "complete"
    reason: str = ""
    sim_s: float = 0.0
    wall_s: float = 0.0
    bench: str = ""  # which bench ran it, in words (benchlab.provenance.bench_text)

    def lines(self) -> list[str]:
        rate = self.frames_lost / max(1, self.frames_ok + self.frames_lost)
        ev = ", ".join(f"{k} {v}" for k, v in sorted(self.events.items())) or "none"
        speed = f" ({self.sim_s / self.wall_s:.0f}x real time)" if self.wall_s > 0 else ""
        return [f"run {self.status}{': ' + self.reason if self.reason else ''}",
                *([f"  bench       {self.bench}"] if self.bench else []),
                f"  cycles      {self.cycles_done} of {self.cycles_planned}",
                f"  duration    {self.sim_s:.0f} s of bench time in {self.wall_s:.1f} s{speed}",
                f"  energy      {self.energy_j / 1e3:.1f} kJ in {self.engagements} engagements",
                f"  peak        T_flywheel {self.peak['T_flywheel']:.1f} degC, T_air {self.peak['T_air']:.1f} degC",
                f"  drop-outs   {rate * 100:.2f} % of flywheel frames lost ({self.frames_lost} of "
                f"{self.frames_ok + self.frames_lost})",
                f"  events      {ev}"]


class Runner:
    """Runs `steps` on `bench`, writing into `writer`; `run()` returns the summary (status complete/aborted)."""

    def __init__(self, bench: Bench, clock: Clock, steps: Sequence[Step], writer: RunWriter, limits: BenchLimits, *,
                 tick_s: float, fast_tick_s: float, dt: float,
                 progress: Task = Task(), progress_every_s: float = 0.5) -> None:
        self.bench, self.clock, self.steps, self.writer, self.limits = bench, clock, tuple(steps), writer, limits
        self.tick_s, self.fast_tick_s, self.dt = tick_s, fast_tick_s, dt
        self.progress, self.progress_every_s = progress, progress_every_s
        self.engagements = Engagements(limits.max_age_s["clutch_torque"])
        self.interlocks = InterlockSet(limits, armed_at=clock())
        self.summary = RunSummary(len({s.cycle for s in self.steps}))
        self.stop_request: str | None = None
        self.stop_code = 130  # the exit code of the stop asked for (130 SIGINT, 143 SIGTERM)
        self.cycle = -1
        self._step = 0  # index in `steps` of the last step started: the progress bar shows it after it ends too
        self._in_step = False  # between that step's step_start and step_end
        self.synced = True
        self._last_progress = -math.inf
        self._planned_before = np.concatenate([[0.0], np.cumsum([s.expected_s for s in self.steps])])
        self._reported = 0.0
        self._t_step_start = clock()
        self._history: collections.deque[tuple[float, float]] = collections.deque()
        self._commanded = False
        self._safe = OPEN_IDLE  # the safe state commanded last (kept when the run stops)
        self._stages: dict[str, tuple[int, float]] = {}  # active interlock -> (its reaction's stage, when commanded)

    # -- public ---------------------------------------------------------------------------------------
    @property
    def current_step(self) -> int:
        """Index in `steps` of the step under way (the step its events carry), -1 between steps."""
        return self._step if self._in_step else -1

    @property
    def safe(self) -> SafeState:
        """The safe state commanded last: what a failure leaves the bench in (a stopped drive is not restarted)."""
        return self._safe

    def request_stop(self, reason: str, code: int = 130) -> None:
        self.stop_request = reason
        self.stop_code = code

    def _stop_if_asked(self) -> None:
        """Raise Stopped if a stop was asked for (a signal, the session)."""
        if self.stop_request is not None:
            raise Stopped(self.stop_request, self.stop_code)

    def run(self, start_step: int = 0) -> RunSummary:
        wall0, t0 = time.perf_counter(), self.clock()
        self.summary.energy_j = float(self.writer.state.get("energy_j", 0.0) or 0.0) if start_step else 0.0
        if not math.isfinite(self.summary.energy_j):
            self.summary.energy_j = 0.0
        energy0 = self.summary.energy_j
        self.summary.cycles_done = done_before = len({s.cycle for s in self.steps[:start_step]})
        self.writer.state["held"] = 0.0
        self.bench.safe_state(self._safe)
        self._tick(interlocks=False)  # the first readings; the steps' ticks watch the interlocks
        try:
            self._await_inputs()
            i = start_step
            while i < len(self.steps):
                self._stop_if_asked()  # asked before this step began: it commands nothing
                step = self.steps[i]
                try:
                    self._run_step(i, step)
                    i += 1
                    if i == len(self.steps) or self.steps[i].cycle != step.cycle:
                        self.summary.cycles_done += 1
                except _SkipCycle:
                    cycle = step.cycle
                    while i < len(self.steps) and self.steps[i].cycle == cycle:
                        i += 1
                    self.writer.event(self.clock(), "cycle_skipped", cycle, "after an interlock",
                                      step=self.current_step)
                    self.summary.events["cycle_skipped"] += 1
                    self._in_step = False
            if self.summary.events["cycle_skipped"] and self.summary.cycles_done == done_before:
                raise Stopped(f"every cycle skipped after an interlock (none of "
                              f"{self.summary.cycles_planned - done_before} ran)", 1)
            self.bench.safe_state(self._safe)
            self._tick(interlocks=False)  # already safe: nothing left to interlock
            self.writer.event(self.clock(), "run_complete", self.cycle)
            self.progress.advance(self._planned_before[-1] - self._reported)
        except Stopped as stop:
            self.bench.safe_state(self._safe)  # the safe state that held (a stopped drive is not restarted)
            self.writer.event(self.clock(), "run_aborted", self.cycle, stop.reason, step=self.current_step)
            self._tick(interlocks=False)
            self.summary.status, self.summary.reason = "aborted", stop.reason
            self.summary.exit_code = stop.code  # type: ignore[attr-defined]
        self.summary.energy_j = energy0 + self.engagements.total_energy
        self.writer.state["energy_j"] = self.summary.energy_j
        self.summary.engagements = self.engagements.count
        stats = getattr(getattr(self.bench, "gateway", None), "stats", None)
        if stats is not None:
            self.summary.frames_ok, self.summary.frames_lost = stats.frames_ok, stats.lost
        self.summary.sim_s, self.summary.wall_s = self.clock() - t0, time.perf_counter() - wall0
        self.writer.flush(self.clock())
        return self.summary

    def _await_inputs(self) -> None:
        """The readiness gate: no set-point that moves anything before every input the interlocks read has had a
        valid reading since the gate opened (alive now, not merely once) and no controller is lost; Stopped if that
        takes longer than the longest maximum age."""
        t0, wait = self.clock(), max(self.limits.max_age_s.values())
        while True:
            st, now = self.bench.status, self.clock()
            missing = [c for c in self.limits.max_age_s if not st.seen.get(c, -math.inf) > t0] + \
                sorted(st.controllers_bad)
            if not missing:
                break
            if now - t0 > wait:
                raise Stopped(f"not ready: no valid {', '.join(missing)} within {wait:g} s of the start: nothing "
                              f"commanded but the safe state", 1)
            self._tick(interlocks=False)
            self._stop_if_asked()
        self.writer.event(self.clock(), "inputs_ready", self.cycle, f"every interlock input fresh after "
                          f"{self.clock() - t0:.2f} s")

    # -- steps ----------------------------------------------------------------------------------------
    def _run_step(self, index: int, step: Step) -> None:
        now = self.clock()
        self._step, self._in_step = index, True
        if step.cycle != self.cycle:
            self.cycle = step.cycle
            self.synced = True
            self.writer.state["cycle"] = step.cycle
            self.writer.event(now, "cycle_start", step.cycle, _point_text(step), step=index)
        self.writer.state["next_step"] = index
        self._history.clear()
        detail = step.phase + (f" {step.label}" if step.label else "") + (f" {_point_text(step)}" if step.point else "")
        self.writer.event(now, "step_start", step.cycle, detail, step=index)
        if step.label == "cooldown":
            self.writer.event(now, "cooldown_start", step.cycle, _point_text(step), step=index)
        t_end = now + step.duration_s
        self._t_step_start = now
        heat = _Pulses(step, now) if step.phase == "heat" else None
        self._apply(step, heat)
        reason = END_TIME
        while True:
            fast = step.phase == "launch" or (self.bench.status.slipping and heat is None) or self._commanded
            self._commanded = False
            self._tick(fast=fast, until=heat.until if heat is not None else math.inf)
            now = self.clock()
            st = self.bench.status
            if step.phase == "launch" and st.locked and now > self._step_t0 + 2 * self.fast_tick_s:
                self.writer.event(now, "synchronised", step.cycle, f"after {now - self._step_t0:.2f} s", step=index)
                reason = END_SYNCHRONISED
                break
            if step.until and self._conditions_met(step.until, now):
                reason = END_CONDITION
                break
            if now >= t_end - 1e-9:
                if step.phase == "launch":
                    self.synced = False
                    self.writer.event(now, "slip_time_limit", step.cycle,
                                      f"not synchronous after {step.duration_s:g} s: clutch opened", step=index)
                    self.summary.events["slip_time_limit"] += 1
                elif step.until:
                    self.writer.event(now, "timeout", step.cycle, "condition not reached: " +
                                      " or ".join(c.describe() for c in step.until), step=index)
                    self.summary.events["timeout"] += 1
                break
            if heat is not None and heat.update(now, st, self._target(step)):
                self._apply(step, heat)
        if step.label == "cooldown":
            self.writer.event(self.clock(), "cooldown_end", step.cycle, f"{reason}; {_point_text(step)}", step=index,
                              reason=reason)
        self.writer.event(self.clock(), "step_end", step.cycle, f"{step.phase}: {reason}", step=index, reason=reason)
        self.writer.state["next_step"] = index + 1
        self._in_step = False

    @property
    def _step_t0(self) -> float:
        return self._t_step_start

    def _apply(self, step: Step, heat: "_Pulses | None") -> None:
        self._commanded = True  # the next tick comes soon: the controllers take the new set-points at once
        self.bench.command(*setpoints(step, self.synced, heat is not None and heat.on))

    @staticmethod
    def _target(step: Step) -> float:
        return step.until[0].value if step.until else math.inf

    def _conditions_met(self, conditions: Sequence[Condition], now: float) -> bool:
        for c in conditions:  # channels checked against CONDITION_CHANNELS before the run (check_schedule)
            v = getattr(self.bench.status, c.channel)
            if not np.isfinite(v):
                continue
            if c.op == ">=" and v >= c.value:
                return True
            if c.op == "<=" and v <= c.value:
                return True
            if c.op == "steady" and self._steady(c, now):
                return True
        return False

    def _steady(self, c: Condition, now: float) -> bool:
        h = self._history
        times = np.fromiter((p[0] for p in h), float, len(h))
        return c.steady_over(times, np.fromiter((p[1] for p in h), float, len(h)), now)

    # -- the tick ---------------------------------------------------------------------------------------
    def _tick(self, fast: bool = False, interlocks: bool = True, until: float = math.inf) -> None:
        tick = self.fast_tick_s if fast else self.tick_s
        now = self.clock()
        target = round(min(now + tick, max(until, now + self.dt)) / self.dt) * self.dt
        self.clock.sleep_until(target)
        if interlocks:
            self._stop_if_asked()
        readings, events = self.bench.poll()
        now = self.clock()
        w = self.writer
        for stream, t, row in readings:
            w.add(stream, t, row)
        for t, kind, detail in events:
            w.event(t, kind, self.cycle, detail, step=self.current_step)
            self.summary.events[kind] += 1
        st = self.bench.status
        if np.isfinite(st.T_flywheel):
            self._history.append((now, st.T_flywheel))
            while self._history and now - self._history[0][0] > 600.0:
                self._history.popleft()
            self.summary.peak["T_flywheel"] = max(self.summary.peak["T_flywheel"], st.T_flywheel)
        if np.isfinite(st.T_air):
            self.summary.peak["T_air"] = max(self.summary.peak["T_air"], st.T_air)
        eng: list[tuple[str, str]] = []
        self.engagements.update(st, now, eng)
        for kind, detail in eng:
            w.event(now, kind, self.cycle, detail, step=self.current_step)
        w.state["energy_j"] = self.summary.energy_j + self.engagements.total_energy
        w.advance(now)
        self._report(now)
        if interlocks:
            trips = self.interlocks.check(st, self.engagements, now)
            if trips:
                self._hold(trips)

    def _trip(self, trips: list[Trip], now: float) -> None:
        """The trips' first safe states at once (with those already held, the strongest), an `interlock` event per
        trip; abort if any of them says so (the safe state holds: a stuck clutch escalates first, `_settle`)."""
        for trip in trips:
            self._stages[trip.name] = (0, now)
        self._command_safe()
        for trip in trips:
            self.writer.event(now, "interlock", self.cycle, f"{trip.name}: {trip.detail} ({trip.action}); safe "
                              f"state {self._safe.name}", step=self.current_step, reason=trip.name)
            self.summary.events[f"interlock {trip.name}"] += 1
        aborting = [t.name for t in trips if t.action == "abort"]
        if aborting:
            self._settle()
            raise Stopped(f"interlock {', '.join(aborting)}", 1)

    def _command_safe(self) -> None:
        """Command the strongest of the active interlocks' current safe states (never a weaker one than held)."""
        names = [self.limits.reaction(n).stages[k] for n, (k, _) in self._stages.items()] + [self._safe.name]
        self._safe = strongest(names)
        self.bench.safe_state(self._safe)

    def _friction_power_seen(self, now: float) -> bool:
        """Friction power measured from fresh clutch frames (a silent actuator's held torque is no measurement)."""
        st = self.bench.status
        fresh = now - st.seen.get("clutch_torque", -math.inf) <= self.limits.max_age_s["clutch_torque"]
        return fresh and st.friction_power > FRICTION_POWER_SEEN_W

    def _escalate(self, now: float) -> bool:
        """Friction power still measured `escalate_after_s` after a safe state: the next stage of each reaction
        waiting that long (an event each); past the last, abort with an alarm. True once any reaction escalated."""
        if self._friction_power_seen(now):
            moved = []
            for name, (k, t) in self._stages.items():
                reaction = self.limits.reaction(name)
                if now - t < reaction.escalate_after_s:
                    continue
                if k + 1 == len(reaction.stages):
                    raise Stopped(f"alarm: {name}: friction power {self.bench.status.friction_power / 1e3:.1f} kW "
                                  f"still measured {now - t:.1f} s after {reaction.stages[k]}", 1)
                self._stages[name] = (k + 1, now)
                moved.append((name, f"{name}: friction power {self.bench.status.friction_power / 1e3:.1f} kW "
                                    f"{now - t:.1f} s after {reaction.stages[k]} -> {reaction.stages[k + 1]}"))
            if moved:
                self._command_safe()
                for name, detail in moved:
                    self.writer.event(now, "safe_state_escalated", self.cycle, detail, step=self.current_step,
                                      reason=name)
                    self.summary.events["safe_state_escalated"] += 1
        return any(k > 0 for k, _ in self._stages.values())

    def _settle(self) -> None:
        """Before an abort: hold the safe state while friction power is measured, escalating (`_escalate`), so the
        run ends with the clutch no longer slipping or with an alarm."""
        while self._friction_power_seen(self.clock()):
            self._tick(interlocks=False)
            self._escalate(self.clock())

    def _hold(self, trips: list[Trip]) -> None:
        """Safe state until every active interlock has cleared for `resume_after_s`, then the next cycle."""
        now = t_trip = self.clock()
        self._trip(trips, now)
        self.writer.state["held"] = 1.0
        t_clear = None
        while True:
            self._tick(interlocks=False)
            self._stop_if_asked()
            now, st = self.clock(), self.bench.status
            more = self.interlocks.check(st, self.engagements, now)
            if more:
                self._trip(more, now)
            alarm = self.interlocks.alarm(st, now)
            if alarm is not None:
                raise Stopped(f"alarm: heat the bench cannot switch off ({self._safe.name} held): {alarm}", 1)
            if self._escalate(now) and not self._friction_power_seen(now):
                raise Stopped(f"{', '.join(self.interlocks.active) or 'interlock'}: the clutch did not open when "
                              f"commanded; stopped in {self._safe.name}", 1)
            if self.interlocks.release(st, self.engagements, now) and not st.slipping:
                t_clear = now if t_clear is None else t_clear
                if now - t_clear >= self.limits.resume_after_s:
                    break
            else:
                t_clear = None
            if now - t_trip > self.limits.max_wait_s:
                names = ", ".join(self.interlocks.active)
                raise Stopped(f"interlock {names} did not clear within {self.limits.max_wait_s:g} s", 1)
        self.writer.state["held"] = 0.0
        self._safe, self._stages = OPEN_IDLE, {}
        self.writer.event(self.clock(), "interlock_cleared", self.cycle, ", ".join(t.name for t in trips),
                          step=self.current_step)
        raise _SkipCycle()

    def _report(self, now: float) -> None:
        """The progress bar: planned seconds done (finished steps, the current one up to its expected length)."""
        wall = time.perf_counter()
        if wall - self._last_progress < self.progress_every_s:
            return
        self._last_progress = wall
        index = min(self._step, len(self.steps) - 1)
        step = self.steps[index]
        done = self._planned_before[index] + min(max(now - self._t_step_start, 0.0), step.expected_s)
        self.progress.advance(done - self._reported)
        self._reported = done
        self.progress.note(f"cycle {step.cycle + 1}/{self.summary.cycles_planned} {step.phase} {step.label} "
                           f"T_flywheel {self.bench.status.T_flywheel:.1f} degC")


class _Pulses:
    """Pulsed heating: slip `pulse_s`, rest `rest_s`, the shaft held by the load.

    A pulse starts only while the flywheel is below the target minus half the rise of the previous pulse,
    so the saw-tooth the pulses leave is centred on the target.
    """

    def __init__(self, step: Step, now: float) -> None:
        self.step = step
        self.on = False
        self.until = now + 2.0  # let the shaft come to rest under the holding load first
        self.rise = 0.0
        self._t_start_temp = math.nan

    def update(self, now: float, st: BenchStatus, target: float) -> bool:
        """Advance the pulse state; True if the set-points must change."""
        if now < self.until - 1e-9:
            return False
        if self.on:
            self.on, self.until = False, now + self.step.rest_s
            if np.isfinite(st.T_flywheel) and np.isfinite(self._t_start_temp):
                self.rise = max(0.0, st.T_flywheel - self._t_start_temp)
            return True
        held = np.isfinite(st.clutch_speed) and abs(st.clutch_speed) < 20.0
        if held and np.isfinite(st.T_flywheel) and pulse_due(st.T_flywheel, target, self.rise):
            self.on, self.until = True, now + self.step.pulse_s
            self._t_start_temp = st.T_flywheel
            return True
        self.until = now + (self.step.rest_s if held else 0.5)
        return False


def _point_text(step: Step) -> str:
    return " ".join(f"{k}={v:g}" for k, v in step.point)
