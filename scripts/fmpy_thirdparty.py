#!/usr/bin/env python3
"""FMPy reference results for the third-party FMUs of fmus/thirdparty/, printed as ONE JSON object.

fdimc's tests call this script as a subprocess and parse its standard output, which is always a
single JSON object (nothing else is written to stdout: the FMU's own printf output, FMPy's messages
and Python warnings are sent to stderr). It supports FMI 2.0 and FMI 3.0 FMUs and computes, with
FMPy only (independently of fdimc):

  cs FMU --step H --stop T [--set NAME=VALUE ...]
      Co-simulation with fmpy.simulate_fmu(fmi_type='CoSimulation', step_size=H,
      output_interval=H, start_values={...}) from t = 0 to T. The FMU integrates internally
      (the OpenModelica FMUs use explicit Euler with the communication step; the Reference
      FMUs have a fixed internal step, see fmus/thirdparty/README.md).

  me FMU --step H --stop T [--rtol 1e-10] [--set NAME=VALUE ...]
      Model exchange integrated by FMPy's CVode (solver='CVode', relative_tolerance=RTOL),
      state events and time events handled by FMPy; output only at the regular points k*H
      (record_events=False, so no duplicate rows at event instants).

      Both print {"time": [...], "<name>": [...], ...} with one column per real output (the
      <ModelStructure> outputs of type Real / Float64 / Float32) and per continuous state
      (the variable referenced by the `derivative` attribute of each <Derivatives> /
      <ContinuousStateDerivative> entry); array variables (FMI 3.0) are flattened into columns
      "name[1]", "name[2]", ... (row-major, 1-based). Non-finite values are written as null.
      Also "columns" (the column names in order), "fmi_version", "interface", "log" (messages the
      FMU sent to its logger with status warning or worse), "fmu_output" (the last 4000 characters
      the FMU or FMPy printed to stdout, e.g. the OpenModelica runtime's assert messages such as
      "division by zero ... m1", which it prints instead of logging when logging is off), "wall_s".
      If the FMU or FMPy fails, the object additionally holds "error": "<message>" and the rows
      recorded before the failure; the exit code is still 0, so the caller sees what FMPy saw.

  jacobian FMU [--set NAME=VALUE ...] [--rel-step 1e-6] [--naive]
      Model exchange through FMPy's low-level API (FMU2Model / FMU3Model): instantiate, set the
      start values, enter/exit initialization mode, event iteration (newDiscreteStates /
      updateDiscreteStates) until converged, enterContinuousTimeMode; read the states x0 and
      compute by central differences, with step h_k = REL_STEP * max(|x0_k|, 1) (for Float32
      inputs max(REL_STEP, 1e-3) * max(|u|, 1)):
          A = d derivatives / d x,  C = d outputs / d x,  B = d derivatives / d u,  D = d outputs / d u
      for all continuous states x and all continuous real inputs u.
      Every evaluation does: set the inputs, setContinuousStates(x), get the outputs FIRST, then
      setContinuousStates(x) again and get the derivatives. This order matters for the
      OpenModelica FMUs: their fmi2GetDerivatives evaluates only the ODE part and clears the
      "needs update" flag, so an fmi2GetReal issued after it returns outputs computed for the
      previous states (stale). --naive uses the naive order (derivatives first, then outputs)
      to show that effect.
      Prints {"fmi_version", "states", "derivatives", "inputs", "outputs", "x0", "dx0", "u0",
      "y0", "A", "B", "C", "D", "steps_x", "steps_u", "declared_dependencies": {"outputs": {name:
      [names] or null}, "derivatives": {...}}, "order": "outputs-first" | "naive", "log",
      "wall_s"} (matrices as lists of rows; rows of A and B follow "derivatives", rows of C and D
      follow "outputs"; null in declared_dependencies means "depends on everything").
      Errors are reported as in cs/me ({"error": ...}, "fmu_output", exit code 0).

--set NAME=VALUE sets a start value before initialisation (parameters, inputs, states with
initial="exact"); VALUE is a number, true/false, or for an FMI 3.0 array the elements separated by
spaces or commas (for example --set "A=0,1,0,0,0,1,-1,-2,-3").

Usage (FMPy is BSD-2-Clause, https://github.com/CATIA-Systems/FMPy, and is NOT a dependency of
fdimc, only of this script; numpy comes with it):

    python3 -m venv /tmp/fmpy-venv && /tmp/fmpy-venv/bin/pip install fmpy==0.3.32
    /tmp/fmpy-venv/bin/python scripts/fmpy_thirdparty.py cs fmus/thirdparty/om_mass_damper.fmu --step 0.001 --stop 1
    /tmp/fmpy-venv/bin/python scripts/fmpy_thirdparty.py me fmus/thirdparty/ref2_bouncing_ball.fmu --step 0.01 --stop 3
    /tmp/fmpy-venv/bin/python scripts/fmpy_thirdparty.py jacobian fmus/thirdparty/om_mass_spring.fmu --set k2=2

Each call takes well under a second on the FMUs of fmus/thirdparty/ (see the README there).
"""
import argparse
import json
import math
import os
import shutil
import sys
import time
import warnings
from ctypes import c_double

import numpy as np

REAL_TYPES = ("Real", "Float64", "Float32")


# ----------------------------------------------------------------------------- output plumbing

class _Stdout:
    """Keep the real stdout for the JSON. While the FMU runs, fd 1 (the FMU's printf output,
    e.g. the OpenModelica runtime's assert messages, and Python prints) goes to a temporary
    file, whose text is copied to stderr and returned in "fmu_output"."""

    def __init__(self):
        import tempfile
        sys.stdout.flush()
        self.fd = os.dup(1)
        self.tmp = tempfile.TemporaryFile()
        os.dup2(self.tmp.fileno(), 1)

    def captured(self):
        sys.stdout.flush()
        self.tmp.seek(0)
        text = self.tmp.read().decode("utf-8", "replace")
        if text:
            sys.stderr.write(text)
            sys.stderr.flush()
        return text[-4000:]

    def emit(self, obj):
        data = (json.dumps(obj, allow_nan=False) + "\n").encode("utf-8")
        with os.fdopen(self.fd, "wb") as f:
            f.write(data)


def _finite(v):
    v = float(v)
    return v if math.isfinite(v) else None


def _flat_names(variable):
    """Column names of a (possibly array) variable: name, or name[1], name[2], ... (row-major)."""
    shape = tuple(variable.shape or ())
    if not shape:
        return [variable.name]
    return [variable.name + "[" + ",".join(str(i + 1) for i in idx) + "]" for idx in np.ndindex(*shape)]


def _size(variable):
    n = 1
    for d in (variable.shape or ()):
        n *= int(d)
    return n


def _parse_sets(pairs):
    start_values = {}
    for p in pairs or []:
        if "=" not in p:
            raise SystemExit(f"--set expects NAME=VALUE, got {p!r}")
        name, value = p.split("=", 1)
        # FMPy converts strings with the variable's own type; arrays are whitespace separated
        start_values[name.strip()] = value.replace(",", " ").strip()
    return start_values


def _check_names(md, start_values):
    names = {v.name for v in md.modelVariables}
    unknown = [n for n in start_values if n not in names]
    if unknown:
        raise ValueError("unknown variable(s) in --set: " + ", ".join(unknown))


def _loggers(log):
    """Python logger callbacks for FMPy (FMI 2.0 signature, FMI 3.0 signature)."""
    labels = ["ok", "warning", "discard", "error", "fatal", "pending"]

    def text(b):
        return b.decode("utf-8", "replace") if isinstance(b, (bytes, bytearray)) else str(b)

    def add(status, category, message):
        status = int(status)
        line = f"[{labels[status] if 0 <= status < len(labels) else status}] {text(category)}: {text(message)}"
        print(line, file=sys.stderr)
        if status >= 1 and len(log) < 200:
            log.append(line)

    def fmi2_logger(component, instance_name, status, category, message):
        add(status, category, message)

    def fmi3_logger(instance_environment, status, category, message):
        add(status, category, message)

    return fmi2_logger, fmi3_logger


def _states(md):
    """[(state variable, derivative variable)] in the order of <Derivatives>."""
    return [(d.variable.derivative, d.variable) for d in md.derivatives]


def _real_outputs(md):
    return [o.variable for o in md.outputs if o.variable.type in REAL_TYPES]


def _real_inputs(md):
    return [v for v in md.modelVariables
            if v.causality == "input" and v.type in REAL_TYPES and v.variability in (None, "continuous")]


# ----------------------------------------------------------------------------- cs / me

def simulate(kind, fmu_path, step, stop, rtol, start_values, debug_logging):
    import fmpy.simulation as fsim
    from fmpy import read_model_description, simulate_fmu

    t0 = time.time()
    out = {"fmi_version": None, "interface": "CoSimulation" if kind == "cs" else "ModelExchange"}
    log = []
    captured = {}

    class CapturingRecorder(fsim.Recorder):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            captured["recorder"] = self

    columns_vars = []
    try:
        md = read_model_description(fmu_path, validate=False)
        out["fmi_version"] = md.fmiVersion
        _check_names(md, start_values)
        seen = set()
        for v in _real_outputs(md) + [s for s, _ in _states(md)]:
            if v.name not in seen:
                seen.add(v.name)
                columns_vars.append(v)
        fmi2_logger, fmi3_logger = _loggers(log)
        logger = fmi2_logger if md.fmiVersion in ("1.0", "2.0") else fmi3_logger
        fsim.Recorder = CapturingRecorder
        kwargs = dict(
            start_time=0.0, stop_time=stop, output_interval=step, start_values=start_values,
            output=[v.name for v in columns_vars], logger=logger, debug_logging=debug_logging,
            model_description=md, validate=False)
        if kind == "cs":
            simulate_fmu(fmu_path, fmi_type="CoSimulation", step_size=step, **kwargs)
        else:
            simulate_fmu(fmu_path, fmi_type="ModelExchange", solver="CVode", step_size=step,
                         relative_tolerance=rtol, record_events=False, **kwargs)
    except BaseException as e:  # noqa: BLE001 - report whatever FMPy / the FMU raised
        if isinstance(e, KeyboardInterrupt):
            raise
        out["error"] = f"{type(e).__name__}: {e}"
    finally:
        fsim.Recorder = CapturingRecorder.__mro__[1]

    rec = captured.get("recorder")
    rows = rec.rows if rec is not None else []
    columns = ["time"]
    data = {"time": [_finite(r[0]) for r in rows]}
    if rec is not None:
        # recorder column order: ("time", var1, var2, ...) grouped by type
        rec_names = [c[0] for c in rec.cols]
        for v in columns_vars:
            if v.name not in rec_names:
                continue
            j = rec_names.index(v.name)
            names = _flat_names(v)
            for k, cname in enumerate(names):
                data[cname] = [_finite(np.asarray(r[j]).ravel()[k]) for r in rows]
                columns.append(cname)
    out["columns"] = columns
    out.update(data)
    out["log"] = log
    out["wall_s"] = round(time.time() - t0, 4)
    return out


# ----------------------------------------------------------------------------- jacobian

class _Model:
    """Thin wrapper around FMPy's FMU2Model / FMU3Model for the Jacobian evaluation."""

    def __init__(self, fmu_path, md, start_values, log, debug_logging):
        from fmpy import extract
        from fmpy.simulation import apply_start_values, settable_in_instantiated, settable_in_initialization_mode

        self.md = md
        self.fmi3 = md.fmiVersion.startswith("3.")
        if md.modelExchange is None:
            raise ValueError("the FMU has no ModelExchange interface")
        self.unzipdir = extract(fmu_path)
        fmi2_logger, fmi3_logger = _loggers(log)
        self._cb = None
        kw = dict(guid=md.guid, unzipDirectory=self.unzipdir,
                  modelIdentifier=md.modelExchange.modelIdentifier, instanceName="fmpy_thirdparty")
        if self.fmi3:
            from fmpy.fmi3 import FMU3Model
            self.fmu = FMU3Model(**kw)
            self.fmu.instantiate(loggingOn=debug_logging, logMessage=fmi3_logger)
        else:
            from fmpy.fmi2 import FMU2Model, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, \
                fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, calloc, free
            from ctypes import byref
            cb = fmi2CallbackFunctions()
            cb.logger = fmi2CallbackLoggerTYPE(fmi2_logger)
            cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            try:
                from fmpy.logging import addLoggerProxy
                addLoggerProxy(byref(cb))
            except Exception as e:  # noqa: BLE001
                print(f"no logger proxy: {e}", file=sys.stderr)
            self._cb = cb
            self.fmu = FMU2Model(**kw)
            self.fmu.instantiate(callbacks=cb, loggingOn=debug_logging)
        fmu = self.fmu
        sv = dict(start_values)
        if self.fmi3:
            sv = apply_start_values(fmu, md, sv, settable=settable_in_instantiated)
            fmu.enterInitializationMode(startTime=0.0)
            sv = apply_start_values(fmu, md, sv, settable=settable_in_initialization_mode)
            fmu.exitInitializationMode()
            need = True
            while need:
                need, terminate, _, _, _, _ = fmu.updateDiscreteStates()
                if terminate:
                    raise RuntimeError("the FMU requested termination during the initial event iteration")
        else:
            fmu.setupExperiment(startTime=0.0)
            sv = apply_start_values(fmu, md, sv, settable=settable_in_instantiated)
            fmu.enterInitializationMode()
            sv = apply_start_values(fmu, md, sv, settable=settable_in_initialization_mode)
            fmu.exitInitializationMode()
            need = True
            while need:
                need, terminate, _, _, _, _ = fmu.newDiscreteStates()
                if terminate:
                    raise RuntimeError("the FMU requested termination during the initial event iteration")
        if sv:
            raise ValueError("could not set start values of: " + ", ".join(sv))
        fmu.enterContinuousTimeMode()
        self.nx = md.numberOfContinuousStates
        self._x = (c_double * max(self.nx, 1))()
        self._dx = (c_double * max(self.nx, 1))()

    # --- typed access to (possibly array) real variables
    def get(self, variable):
        n = _size(variable)
        if not self.fmi3:
            return list(self.fmu.getReal([variable.valueReference]))
        getter = self.fmu.getFloat32 if variable.type == "Float32" else self.fmu.getFloat64
        return list(getter([variable.valueReference], nValues=n))

    def set(self, variable, values):
        if not self.fmi3:
            self.fmu.setReal([variable.valueReference], list(values))
        elif variable.type == "Float32":
            self.fmu.setFloat32([variable.valueReference], list(values))
        else:
            self.fmu.setFloat64([variable.valueReference], list(values))

    def get_x(self):
        if self.nx == 0:
            return []
        self.fmu.getContinuousStates(self._x, self.nx)
        return list(self._x[:self.nx])

    def set_x(self, x):
        if self.nx == 0:
            return
        for i, v in enumerate(x):
            self._x[i] = v
        self.fmu.setContinuousStates(self._x, self.nx)

    def get_dx(self):
        if self.nx == 0:
            return []
        if self.fmi3:
            self.fmu.getContinuousStateDerivatives(self._dx, self.nx)
        else:
            self.fmu.getDerivatives(self._dx, self.nx)
        return list(self._dx[:self.nx])

    def close(self):
        try:
            self.fmu.terminate()
        except Exception as e:  # noqa: BLE001
            print(f"terminate failed: {e}", file=sys.stderr)
        try:
            self.fmu.freeInstance()
        except Exception as e:  # noqa: BLE001
            print(f"freeInstance failed: {e}", file=sys.stderr)
        shutil.rmtree(self.unzipdir, ignore_errors=True)


def jacobian(fmu_path, start_values, rel_step, naive, debug_logging):
    from fmpy import read_model_description

    t0 = time.time()
    log = []
    out = {"fmi_version": None, "order": "naive" if naive else "outputs-first"}
    model = None
    try:
        md = read_model_description(fmu_path, validate=False)
        out["fmi_version"] = md.fmiVersion
        _check_names(md, start_values)
        states = _states(md)
        outputs = _real_outputs(md)
        inputs = _real_inputs(md)
        out["states"] = [n for s, _ in states for n in _flat_names(s)]
        out["derivatives"] = [n for _, d in states for n in _flat_names(d)]
        out["inputs"] = [n for v in inputs for n in _flat_names(v)]
        out["outputs"] = [n for v in outputs for n in _flat_names(v)]

        def deps(unknowns):
            return {u.variable.name: (None if u.dependencies is None else [d.name for d in u.dependencies])
                    for u in unknowns}
        out["declared_dependencies"] = {"outputs": deps(md.outputs), "derivatives": deps(md.derivatives)}

        model = _Model(fmu_path, md, start_values, log, debug_logging)
        if model.nx != len(out["states"]):
            raise RuntimeError(f"numberOfContinuousStates = {model.nx} but <Derivatives> lists "
                               f"{len(out['states'])} state elements")
        u0 = [[float(e) for e in model.get(v)] for v in inputs]  # per input variable (arrays kept together)

        def evaluate(x, u):
            for v, val in zip(inputs, u):
                model.set(v, val)
            if naive:
                model.set_x(x)
                dx = model.get_dx()
                y = [e for v in outputs for e in model.get(v)]
            else:
                model.set_x(x)
                y = [e for v in outputs for e in model.get(v)]
                model.set_x(x)
                dx = model.get_dx()
            return [float(e) for e in dx], [float(e) for e in y]

        x0 = [float(e) for e in model.get_x()]
        dx0, y0 = evaluate(x0, u0)
        nx, ny = len(x0), len(y0)
        A = [[0.0] * nx for _ in range(nx)]
        C = [[0.0] * nx for _ in range(ny)]
        steps_x = []
        for k in range(nx):
            h = rel_step * max(abs(x0[k]), 1.0)
            steps_x.append(h)
            xp, xm = list(x0), list(x0)
            xp[k] += h
            xm[k] -= h
            dp, yp = evaluate(xp, u0)
            dm, ym = evaluate(xm, u0)
            for i in range(nx):
                A[i][k] = (dp[i] - dm[i]) / (2 * h)
            for i in range(ny):
                C[i][k] = (yp[i] - ym[i]) / (2 * h)
        flat_u = [(j, e) for j, v in enumerate(inputs) for e in range(_size(v))]
        nu = len(flat_u)
        B = [[0.0] * nu for _ in range(nx)]
        D = [[0.0] * nu for _ in range(ny)]
        steps_u = []
        for k, (j, e) in enumerate(flat_u):
            base = u0[j][e]
            r = max(rel_step, 1e-3) if inputs[j].type == "Float32" else rel_step
            h = r * max(abs(base), 1.0)
            steps_u.append(h)
            up = [list(a) for a in u0]
            um = [list(a) for a in u0]
            up[j][e] = base + h
            um[j][e] = base - h
            dp, yp = evaluate(x0, up)
            dm, ym = evaluate(x0, um)
            for i in range(nx):
                B[i][k] = (dp[i] - dm[i]) / (2 * h)
            for i in range(ny):
                D[i][k] = (yp[i] - ym[i]) / (2 * h)
        evaluate(x0, u0)  # leave the FMU at the nominal point

        def fin(m):
            return [[_finite(v) for v in row] for row in m]
        out.update({
            "x0": [_finite(v) for v in x0], "dx0": [_finite(v) for v in dx0],
            "u0": [_finite(v) for a in u0 for v in a], "y0": [_finite(v) for v in y0],
            "A": fin(A), "B": fin(B), "C": fin(C), "D": fin(D),
            "steps_x": steps_x, "steps_u": steps_u,
        })
    except BaseException as e:  # noqa: BLE001
        if isinstance(e, KeyboardInterrupt):
            raise
        out["error"] = f"{type(e).__name__}: {e}"
    finally:
        if model is not None:
            model.close()
    out["log"] = log
    out["wall_s"] = round(time.time() - t0, 4)
    return out


# ----------------------------------------------------------------------------- main

def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    for name in ("cs", "me"):
        s = sub.add_parser(name)
        s.add_argument("fmu")
        s.add_argument("--step", type=float, required=True)
        s.add_argument("--stop", type=float, required=True)
        s.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
        s.add_argument("--debug-logging", action="store_true")
        if name == "me":
            s.add_argument("--rtol", type=float, default=1e-10)
    s = sub.add_parser("jacobian")
    s.add_argument("fmu")
    s.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    s.add_argument("--rel-step", type=float, default=1e-6)
    s.add_argument("--naive", action="store_true",
                   help="get the derivatives before the outputs (shows the stale-output caching of OpenModelica FMUs)")
    s.add_argument("--debug-logging", action="store_true")
    args = p.parse_args(argv)

    stdout = _Stdout()
    warnings.simplefilter("default")
    start_values = _parse_sets(args.set)
    fmu = os.path.abspath(args.fmu)
    if args.cmd == "jacobian":
        result = jacobian(fmu, start_values, args.rel_step, args.naive, args.debug_logging)
    else:
        result = simulate(args.cmd, fmu, args.step, args.stop, getattr(args, "rtol", None),
                          start_values, args.debug_logging)
    result = {"command": args.cmd, "fmu": os.path.basename(fmu), **result,
              "fmu_output": stdout.captured()}
    stdout.emit(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
