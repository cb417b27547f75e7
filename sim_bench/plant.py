"""The simulated bench's thermal plant: the paper's network plus effects the identification model lacks.

Each effect is switchable and scaled and is an edit of the true network, written here on the
bench side independently of what `benchlab.diagnose` knows, so that hiding an effect in
simulated data and finding it again is a real test. Effects that depend on the plant's own
temperatures (radiation, natural convection) are solved by fixed-point iteration over the whole horizon.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from benchlab.model.clutch import clutch_network, convection_resistance
from benchlab.network import Calibration, Lag, Link, Node, Source, ThermalNetwork
from benchlab.model.params import paper_params
from benchlab.network.plant import NetworkPlant

STEFAN_BOLTZMANN = 5.670374419e-8
KELVIN = 273.15

Edit = Callable[[ThermalNetwork, dict[str, float]], ThermalNetwork]


@dataclass(frozen=True)
class Effect:
    """A physical effect of the bench: its name, the signal it depends on, its mechanism, the network edit."""

    name: str
    signal: str | None
    mechanism: str
    edit: Edit
    params: Mapping[str, float] = field(default_factory=dict)
    reads_states: bool = False  # its laws read the plant's own temperatures: solved by fixed-point iteration
    switches: tuple["Thermostat", ...] = ()  # thermostats the plant switches period by period and carries on


def _drop_convection(link: Link) -> bool:
    return link.label not in ("R_PA", "R_FA")


def slip_convection(gain_per_krpm: float) -> Effect:
    """Convection grows with slip speed: R = f_R(ω_e, S) / (1 + g·|Δω|/1000 rpm)."""
    def law(p, ch):
        slip = np.abs(ch["engine_speed"] - ch["clutch_speed"])
        return convection_resistance(p, ch) / (1.0 + p["slip_gain"] * slip / 1000.0)

    def edit(net, p):
        return net.replace_links(_drop_convection, (Link("P", "A", law, "R_PA"), Link("F", "A", law, "R_FA")))
    return Effect("slip_convection", "slip_speed", "convection", edit, {"slip_gain": gain_per_krpm})


def heat_split(plate_fraction: float) -> Effect:
    """The friction power goes `plate_fraction` to the pressure plate, the rest to the flywheel."""
    def edit(net, p):
        return replace(net, sources=(Source("P", lambda q, ch: q["split"] * ch["friction_power"], "plate share"),
                                     Source("F", lambda q, ch: (1 - q["split"]) * ch["friction_power"], "flywheel share"))
                       + tuple(s for s in net.sources if s.label not in ("plate share", "flywheel share")))
    return Effect("heat_split", "friction_power", "heat_split", edit, {"split": plate_fraction})


def gearbox_churning(watts_at_2000rpm: float) -> Effect:
    """Gearbox losses heat the housing in proportion to the input-shaft speed squared."""
    def edit(net, p):
        return net.with_source(Source("T", lambda q, ch: q["churn_w"] * (ch["clutch_speed"] / 2000.0) ** 2,
                                      "gearbox churning"))
    return Effect("gearbox_churning", "clutch_speed", "heat_source", edit, {"churn_w": watts_at_2000rpm})


def engine_heat(watts_at_2000rpm: float) -> Effect:
    """An engine-side heat flow into the flywheel growing with engine speed (bearing and motor losses)."""
    def edit(net, p):
        return net.with_source(Source("F", lambda q, ch: q["engine_w"] * (ch["engine_speed"] / 2000.0),
                                      "engine heat"))
    return Effect("engine_heat", "engine_speed", "heat_source", edit, {"engine_w": watts_at_2000rpm})


def plate_conduction(resistance_k_per_w: float) -> Effect:
    """Pressure plate and flywheel exchange heat through the clamped disc when S = 1."""
    def law(p, ch):
        return np.where(ch["clutch_state"] >= 0.5, p["R_PF"], 1e6)

    def edit(net, p):
        return net.with_link(Link("P", "F", law, "R_PF"))
    return Effect("plate_conduction", "clutch_state", "conduction", edit, {"R_PF": resistance_k_per_w})


def contact_conduction(resistance_k_per_w: float, signal: str | None = None, reference: float = 1.0) -> Effect:
    """Pressure plate and flywheel exchange heat through a contact whatever the clutch state: a resistance
    `resistance_k_per_w`, or with `signal` a conductance in proportion to |signal| / `reference` (a contact pressed
    by the clutch torque), no contact where the signal is zero."""
    def law(p, ch):
        if signal is None:
            return np.full(len(ch["clutch_state"]), p["R_contact"])
        share = np.abs(ch[signal]) / reference
        return np.where(share > 1e-6, p["R_contact"] / np.maximum(share, 1e-6), 1e6)

    def edit(net, p):
        return net.with_link(Link("P", "F", law, "R_contact"))
    return Effect("contact_conduction", signal, "conduction", edit, {"R_contact": resistance_k_per_w})


def sensor_lag(time_constant_s: float) -> Effect:
    """The flywheel sensors follow the flywheel surface with a first-order lag."""
    def edit(net, p):
        return net.with_lag(Lag("F_sensor", "F", "tau_F"), "T_flywheel")
    return Effect("sensor_lag", "T_flywheel", "sensor", edit, {"tau_F": time_constant_s})


def sensor_calibration(channel: str, offset_k: float, gain: float, drift_k_per_s: float = 0.0) -> Effect:
    """The PT1000 of `channel` is miscalibrated (a wrong curve, a lead resistance): it reads
    `gain`·T + `offset_k` + `drift_k_per_s`·t where the plant's readings are made (`sensor_temperatures`)."""
    def edit(net, p):
        return replace(net, calibrations={**net.calibrations, channel: Calibration(
            f"cal_gain_{channel}", f"cal_offset_{channel}", f"cal_drift_{channel}")})
    return Effect("sensor_calibration", channel, "sensor", edit,
                  {f"cal_gain_{channel}": gain, f"cal_offset_{channel}": offset_k,
                   f"cal_drift_{channel}": drift_k_per_s})


def extra_mass(capacity_j_per_k: float, resistance_k_per_w: float) -> Effect:
    """A hub mass behind the flywheel stores heat: an extra node linked to the flywheel."""
    def edit(net, p):
        return net.with_node(Node("H", "C_H"), "T_flywheel").with_link(Link("F", "H", lambda q, ch: q["R_FH"], "R_FH"))
    return Effect("extra_mass", None, "capacity", edit, {"C_H": capacity_j_per_k, "R_FH": resistance_k_per_w})


def capacity_temperature(node: str, channel: str, per_k: float, reference_c: float = 25.0) -> Effect:
    """The heat capacity C of node `node` (measured as `channel`) rises with its own temperature, as a metal's
    specific heat does: C·(1 + β·(ϑ − `reference_c`)) on the plant's own state, solved by fixed-point iteration; the
    state follows dϑ/dt = Q/C(ϑ)."""
    beta = f"beta_C_{node}"

    def edit(net, p):
        def law(q, ch, capacity=next(n.capacity for n in net.nodes if n.name == node)):
            return q[capacity] * (1.0 + q[beta] * (ch[f"_state_{node}"] - reference_c))
        return replace(net, nodes=tuple(replace(n, capacity_law=law) if n.name == node else n for n in net.nodes))
    return Effect("capacity_temperature", channel, "capacity", edit, {beta: per_k}, reads_states=True)


def radiation(emissivity_area_m2: float) -> Effect:
    """Flywheel and plate radiate to the housing: εA·σ·(T⁴ − T_T⁴), solved by fixed-point iteration."""
    def flow(node: str, sign: float):
        def heat(p, ch):
            hot, cold = ch[f"_state_{node}"] + KELVIN, ch["_state_T"] + KELVIN
            return sign * p["eps_area"] * STEFAN_BOLTZMANN * (hot ** 4 - cold ** 4)
        return heat

    def edit(net, p):
        for node in ("F", "P"):
            net = net.with_source(Source(node, flow(node, -1.0), f"radiation {node}"))
            net = net.with_source(Source("T", flow(node, 1.0), f"radiation {node} to housing"))
        return net
    return Effect("radiation", "T_flywheel", "other", edit, {"eps_area": emissivity_area_m2}, reads_states=True)


def natural_convection(resistance_at_10k: float, exponent: float = 0.25) -> Effect:
    """Mixed convection: beside the forced convection of eq. (11), plate and flywheel each lose heat to the chamber
    air by natural convection, whose coefficient grows with their temperature difference (h ~ dT^0.25, laminar):
    a parallel path R_n * (|dT| / 10 K)^-exponent, read from the plant's own temperatures."""
    def path(node: str):
        def law(p, ch):
            difference = np.maximum(np.abs(ch[f"_state_{node}"] - ch["_state_A"]), 0.1)
            return p["R_nat"] * (difference / 10.0) ** -p["n_nat"]
        return law

    def edit(net, p):
        for node in ("P", "F"):
            net = net.with_link(Link(node, "A", path(node), f"natural convection {node}"))
        return net
    return Effect("natural_convection", "T_flywheel", "convection", edit,
                  {"R_nat": resistance_at_10k, "n_nat": exponent}, reads_states=True)


class Thermostat:
    """A thermostat on a plant node: on where the node's temperature, sampled every THERMOSTAT_PERIOD_S, has risen to
    `on_c`, off where it has fallen to `off_c`, kept in between (the bench's own switch, independent of the model
    files' hysteresis). The plant carries it from sample to sample and from one advance to the next; a reset plant
    starts it off. Its law reads it as the channel `channel` (1 while on), held over each period. One plant advances
    it (a plant `with_effects` shares it with its parent, which is then not advanced); a real-time bench's cut
    restores the plant's temperatures, not the switch, which keeps its state at the end of the cut chunk."""

    def __init__(self, node: str, on_c: float, off_c: float, channel: str) -> None:
        self.node, self.on_c, self.off_c, self.channel = node, on_c, off_c, channel
        self.on = False

    def sample(self, temperature_c: float) -> None:
        """The switch after reading the node's temperature."""
        self.on = temperature_c >= self.on_c if not self.on else temperature_c > self.off_c


THERMOSTAT_PERIOD_S = 1.0


def thermostat_fan(link: str, sensed: str, channel: str, on_c: float, off_c: float,
                   conductance_factor: float) -> Effect:
    """A fan switched by a thermostat on the plant's own temperature of node `sensed` (measured as `channel`; on above
    `on_c`, off below `off_c`, its state kept in between): while it runs, link `link` conducts `conductance_factor`
    times as much."""
    switch = Thermostat(sensed, on_c, off_c, f"_thermostat_{link}")

    def edit(net, p):
        base = next(l for l in net.links if l.label == link)

        def law(q, ch):
            return base.resistance(q, ch) / (1.0 + (q["fan_factor"] - 1.0) * ch[switch.channel])
        return net.replace_links(lambda l: l.label != link, (Link(base.a, base.b, law, link),))
    return Effect("thermostat_fan", channel, "convection", edit, {"fan_factor": conductance_factor},
                  switches=(switch,))


def custom_source(name: str, node: str, signal: str, mechanism: str,
                  heat_flow: Callable[[Mapping[str, np.ndarray]], np.ndarray]) -> Effect:
    """A heat flow of any shape into `node`, driven by channels: for effects no model term describes."""
    def edit(net, p):
        return net.with_source(Source(node, lambda q, ch: heat_flow(ch), name))
    return Effect(name, signal, mechanism, edit)


class ThermalPlant(NetworkPlant):
    """True temperatures of the bench for given drivetrain channels; keeps its state between calls.

    By default the paper's network (`name` "paper"); `network` gives another one (sim_bench.reference_plant), whose
    laws read the plant's own temperatures where `reads_states`, and whose `friction` (state name -> degC to the
    factor μ(ϑ)/μ_cal) scales the torque the clutch transmits for what the controller commands."""

    RADIATION_ITERATIONS = 4
    TOLERANCE_K = 1e-3  # a network that reads states (`reads_states`) stops iterating once no state moves this much

    def __init__(self, params: Mapping[str, float] | None = None, effects: Sequence[Effect] = (),
                 network: ThermalNetwork | None = None, reads_states: bool = False,
                 friction: Callable[[Mapping[str, float]], float] | None = None, name: str = "paper") -> None:
        self.params: dict[str, float] = dict(params or paper_params("nonlinear"))
        self.base_network = network or clutch_network()
        network = self.base_network
        for effect in effects:
            self.params.update(effect.params)
            network = effect.edit(network, self.params)
        network.validate()
        self._switches = tuple(switch for e in effects for switch in e.switches)
        super().__init__(network, self.params)
        self.effects = tuple(effects)
        self.reads_states = reads_states
        self.friction = friction
        self.name = name
        self._iterative = reads_states or any(e.reads_states for e in effects)

    def reset(self, temperature_c: float | Mapping[str, float]) -> None:
        """NetworkPlant.reset, the effects' thermostats switched off."""
        super().reset(temperature_c)
        for switch in self._switches:
            switch.on = False

    def advance(self, channels: Mapping[str, np.ndarray], dt: float) -> dict[str, np.ndarray]:
        """NetworkPlant.advance; with thermostats, period by period (THERMOSTAT_PERIOD_S), each switched on the state
        at its period's start."""
        if not self._switches:
            return super().advance(channels, dt)
        n = len(next(iter(channels.values())))
        period = max(1, int(round(THERMOSTAT_PERIOD_S / dt)))
        pieces = []
        for start in range(0, n, period):
            for switch in self._switches:
                switch.sample(float(self.state[self.state_names.index(switch.node)]))
            pieces.append(super().advance({name: values[start:start + period] for name, values in channels.items()},
                                          dt))
        return {name: np.concatenate([piece[name] for piece in pieces]) for name in self.state_names}

    def with_effects(self, effects: Sequence[Effect]) -> "ThermalPlant":
        """The same plant (network, parameters, friction) with `effects` added to its own."""
        return ThermalPlant(self.params, tuple(self.effects) + tuple(effects), self.base_network, self.reads_states,
                            self.friction, self.name)

    def friction_factor(self, state: np.ndarray | None = None) -> float:
        """μ(ϑ)/μ_cal at `state` (the states in `state_names` order; default the current state): 1 for a plant
        without temperature-dependent friction."""
        state = self.state if state is None else state
        if self.friction is None or state is None:
            return 1.0
        return self.friction(dict(zip(self.state_names, state.tolist())))

    def prime(self, channels: Mapping[str, np.ndarray], dt: float) -> None:
        """Compile (or load from numba's cache) the solver kernels `advance` calls, on a few samples of the
        channels it is given (a first-call compile in a real-time run stalls the emulated devices); the state
        is not changed."""
        self._states_from_now(channels, dt)

    def _states_from_now(self, channels: Mapping[str, np.ndarray], dt: float) -> np.ndarray:
        """States (N + 1, n) over `channels` from the current state, which is left as it is."""
        if self.state is None:
            raise RuntimeError("reset() the plant before advancing it")
        channels = dict(channels)
        n = len(next(iter(channels.values())))
        for switch in self._switches:  # held over the period (advance)
            channels[switch.channel] = np.full(n, 1.0 if switch.on else 0.0)
        states = self._run(self._with_states(channels, None), dt)
        for _ in range(self.RADIATION_ITERATIONS if self._iterative else 0):
            previous = states
            states = self._run(self._with_states(channels, states), dt)
            if states.base is not None and states.base is previous.base:  # the stream's last states again
                break  # the laws gave what they gave before: a fixed point, every further pass the same
            if self.reads_states and np.max(np.abs(states - previous)) < self.TOLERANCE_K:
                break  # the reference plant's laws: converged (the paper's effects keep their fixed count)
        return states

    def _with_states(self, channels: dict[str, np.ndarray], states: np.ndarray | None) -> dict[str, np.ndarray]:
        if not self._iterative:
            return channels
        n = len(next(iter(channels.values())))
        for i, name in enumerate(self.state_names):
            channels[f"_state_{name}"] = states[:-1, i] if states is not None else np.full(n, self.state[i])
        return channels
