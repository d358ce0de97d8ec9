"""First-order lag x' = (u - x) / tau, y = x, as a PythonFMU3 (FMI 3.0 co-simulation) slave.

Part of fdimc's FMU conformance suite (a third exporter); see README.md here. The same model as
PythonFmuLag.py: do_step advances x exactly for an input held constant over the step,
x(t + h) = u + (x(t) - u) exp(-h / tau). A non-positive tau is logged (status warning) and
do_step returns False, which the exporter reports to the host as Discard.
Build: `pythonfmu3 build -f PythonFmu3Lag.py`.
"""
import math

from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Status, Fmi3Variability, Float64


class PythonFmu3Lag(Fmi3Slave):

    author = "fdimc"
    description = "First-order lag x' = (u - x)/tau, y = x (exact step, input held over the step)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.u = 0.0
        self.y = 0.0
        self.tau = 0.5
        self.register_variable(Float64("time", causality=Fmi3Causality.independent,
                                       variability=Fmi3Variability.continuous))
        self.register_variable(Float64("u", causality=Fmi3Causality.input,
                                       description="input"))
        self.register_variable(Float64("y", causality=Fmi3Causality.output,
                                       description="output y = x, the lag's state"))
        self.register_variable(Float64("tau", causality=Fmi3Causality.parameter,
                                       variability=Fmi3Variability.fixed,
                                       description="time constant [s]"))

    def do_step(self, current_time, step_size):
        if not self.tau > 0.0:
            self.log(f"tau must be positive, is {self.tau}", Fmi3Status.warning)
            return False
        self.y = self.u + (self.y - self.u) * math.exp(-step_size / self.tau)
        self.time = current_time + step_size
        return True
