"""Open-loop scripted cheetah gaits: a baseline that leaves the zone without any learning.

The gaits were found by random search over sinusoid parameters (see `bench/suite_speed.py` for the
batch they ran on); they carry the cheetah about 15-19 m in one 200-step episode from most initial
poses, backward more reliably than forward. Used by the demo and the tests.
"""

from __future__ import annotations

import numpy as np

from hyperstate.suite.cheetah_dir import BACKWARD, CONTROL_TIMESTEP, FORWARD


class SinusoidGait:
    """Action a_j(t) = amplitude_j * sin(2 pi frequency t + phase_j), t the time since episode start."""

    def __init__(self, frequency: float, amplitude, phase):
        self.frequency = float(frequency)
        self.amplitude = np.asarray(amplitude, dtype=np.float64)
        self.phase = np.asarray(phase, dtype=np.float64)

    def __call__(self, step: int) -> np.ndarray:
        return self.amplitude * np.sin(2 * np.pi * self.frequency * step * CONTROL_TIMESTEP + self.phase)


GAITS = {
    FORWARD: SinusoidGait(3.77, [0.908, 0.521, 0.656, 0.716, 0.806, 0.403], [0.595, 2.154, 1.173, 4.68, 4.012, 3.174]),
    BACKWARD: SinusoidGait(
        3.324, [0.959, 0.546, 0.602, 0.509, 0.983, 0.555], [1.401, 2.754, 3.481, 4.665, 1.257, 5.452]
    ),
}


def gait(direction: float) -> SinusoidGait:
    """The scripted gait running in `direction` (+1 forward, -1 backward)."""
    return GAITS[float(direction)]
