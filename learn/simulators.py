"""Which simulator an environment gets: one in its own process, or a child process of its own
(libsumo holds one simulation per process)."""

from __future__ import annotations

from learn.protocol import Config, Simulator, SimulatorMode, check_simulator_mode
from learn.session import InProcessSimulator
from learn.worker import SimulatorProcess


def open_simulator(config: Config, mode: SimulatorMode) -> Simulator:
    """The simulator for one environment. ``auto``: in this process when nothing else simulates
    here (no IPC or copying per step), else in a child process of its own."""
    check_simulator_mode(mode)
    if mode == "subprocess" or (mode == "auto" and not InProcessSimulator.slot_free()):
        return SimulatorProcess(config)
    if not InProcessSimulator.slot_free():
        raise RuntimeError(
            "simulator='in_process': this process already runs a simulation (libsumo allows one"
            " per process); close it, or use simulator='subprocess'"
        )
    return InProcessSimulator(config)
