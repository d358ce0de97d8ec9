"""First-order lag x' = (u - x) / tau, y = x, as a PythonFMU (FMI 2.0 co-simulation) slave.

Part of fdimc's FMU conformance suite (a third exporter); see README.md here. The slave integrates
itself: do_step advances x exactly for an input held constant over the step (zero-order hold),
x(t + h) = u + (x(t) - u) exp(-h / tau). A non-positive tau is logged (status warning) and
do_step returns False, which the exporter reports to the host as Discard.
Build: `pythonfmu build -f PythonFmuLag.py`.
"""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status


class PythonFmuLag(Fmi2Slave):

    author = "fdimc"
    description = "First-order lag x' = (u - x)/tau, y = x (exact step, input held over the step)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = 0.0
        self.tau = 0.5
        self.register_variable(Real("u", causality=Fmi2Causality.input,
                                    description="input"))
        self.register_variable(Real("y", causality=Fmi2Causality.output,
                                    description="output y = x, the lag's state"))
        self.register_variable(Real("tau", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.fixed,
                                    description="time constant [s]"))

    def do_step(self, current_time, step_size):
        if not self.tau > 0.0:
            self.log(f"tau must be positive, is {self.tau}", Fmi2Status.warning)
            return False
        self.y = self.u + (self.y - self.u) * math.exp(-step_size / self.tau)
        return True
