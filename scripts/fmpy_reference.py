#!/usr/bin/env python3
"""Reference values for the test FMUs of fmus/ computed with FMPy, independent of fdimc.

Builds the FMUs with `cargo run --release --example build_fmus DIR` (or takes an existing build directory) and prints:

1. aircraft.fmu, FMI 2.0 Co-Simulation (the FMU's internal forward Euler, 1 ms steps),
   stop 2 s, output interval 0.01 s, inputs held at their start values elevator_rad = 0.02,
   throttle = 0.46, elevator_effectiveness = 1, all parameters at their defaults:
   V_m_s, alpha_rad, q_rad_s, theta_rad, h_m at t = 0.5, 1.0, 2.0 (17 significant digits),
   and whether a Python copy of the same Euler arithmetic gives the same bits;
2. the same in FMI 2.0 Model Exchange with FMPy's CVode (relative tolerance 1e-10) and
   the CS - ME difference;
3. ewma_detector.fmu with in_1 = 1, in_2 = -3, in_3 = 0.5 for 10 steps of 0.01 s:
   statistic and isolated_channel after each step (and the bit-for-bit Python copy);
4. the aircraft's level-flight trim at V = 53.6 m/s (Newton on dV = dalpha = dq = 0 with
   theta = alpha, q = 0), to 12 digits;
5. the closed loop aircraft_cs.fmu + pitch_controller.fmu (0.01 s steps), from the trim with
   a 0.02 rad elevator_cmd step and from the FMUs' default start;
6. the fail_at_s / abort_at_s test hooks: fmi2DoStep and fmi2GetDerivatives return
   fmi2Error (3) once time >= fail_at_s; abort_at_s kills the process (run in a child).

Usage (FMPy is BSD-2-Clause, https://github.com/CATIA-Systems/FMPy; not a dependency of
fdimc, only of this script):

    python3 -m venv /tmp/fmpy-venv && /tmp/fmpy-venv/bin/pip install fmpy
    /tmp/fmpy-venv/bin/python scripts/fmpy_reference.py            # builds into a temp dir
    /tmp/fmpy-venv/bin/python scripts/fmpy_reference.py /tmp/fmus-out   # uses the FMUs already built there
"""
import math
import os
import subprocess
import sys
import tempfile
import zipfile
from ctypes import c_double

import numpy as np
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model, FMU2Slave

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STATES = ["V_m_s", "alpha_rad", "q_rad_s", "theta_rad", "h_m"]
TIMES = [0.5, 1.0, 2.0]
INPUTS = {"elevator_rad": 0.02, "throttle": 0.46, "elevator_effectiveness": 1.0}

# aircraft defaults, as in fmus/aircraft/FMI2.xml
P = dict(m_kg=1247.0, S_m2=17.09, cbar_m=1.74, Iyy_kg_m2=4067.5, rho_kg_m3=1.225, g_m_s2=9.80665,
         CL0=0.2, CLa=4.44, CLa3=6.0, CLq=3.8, CLde=0.355, CD0=0.05, k_induced=0.0675,
         Cm0=0.05, Cma=-0.683, Cma3=-2.0, Cmq=-9.96, Cmde=-0.923, T_max_N=4000.0,
         V0_m_s=53.6, alpha0_rad=0.05, q0_rad_s=0.0, theta0_rad=0.05, h0_m=1000.0)


def f(x, elevator, throttle, eff, p=P):
    """The aircraft's derivatives, operation for operation as in fmus/aircraft/model.c."""
    V, alpha, q, theta, _h = x
    qbar = 0.5 * p["rho_kg_m3"] * V * V
    qhat = q * p["cbar_m"] / (2.0 * V)
    de = eff * elevator
    CL = p["CL0"] + p["CLa"] * alpha - p["CLa3"] * alpha * alpha * alpha + p["CLq"] * qhat + p["CLde"] * de
    CD = p["CD0"] + p["k_induced"] * CL * CL
    Cm = p["Cm0"] + p["Cma"] * alpha + p["Cma3"] * alpha * alpha * alpha + p["Cmq"] * qhat + p["Cmde"] * de
    L = qbar * p["S_m2"] * CL
    D = qbar * p["S_m2"] * CD
    M = qbar * p["S_m2"] * p["cbar_m"] * Cm
    T = p["T_max_N"] * throttle
    gamma = theta - alpha
    return [(T * math.cos(alpha) - D) / p["m_kg"] - p["g_m_s2"] * math.sin(gamma),
            q - (T * math.sin(alpha) + L) / (p["m_kg"] * V) + p["g_m_s2"] * math.cos(gamma) / V,
            M / p["Iyy_kg_m2"],
            q,
            V * math.sin(gamma)]


def row_at(result, t):
    i = int(np.argmin(np.abs(result["time"] - t)))
    assert abs(result["time"][i] - t) < 1e-9, (t, result["time"][i])
    return result[i]


_WORK = None  # a tempfile.TemporaryDirectory, made by main()


def unzip(path):
    d = tempfile.mkdtemp(dir=_WORK.name)
    zipfile.ZipFile(path).extractall(d)
    return d


def g17(v):
    return f"{float(v):.17g}"


def build(out):
    subprocess.run(["cargo", "run", "--release", "--example", "build_fmus", "--", out], cwd=ROOT, check=True, stdout=subprocess.DEVNULL)


def aircraft_cs_me(out):
    fmu = os.path.join(out, "aircraft.fmu")
    cs = simulate_fmu(fmu, fmi_type="CoSimulation", stop_time=2.0, output_interval=0.01,
                      start_values=INPUTS, output=STATES)
    me = simulate_fmu(fmu, fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10,
                      stop_time=2.0, output_interval=0.01, start_values=INPUTS, output=STATES)

    # a Python copy of the FMU's CS arithmetic: 10 Euler steps of 1e-3 per doStep of 0.01
    x = [P["V0_m_s"], P["alpha0_rad"], P["q0_rad_s"], P["theta0_rad"], P["h0_m"]]
    copy = {}
    for k in range(1, 2001):
        dx = f(x, INPUTS["elevator_rad"], INPUTS["throttle"], INPUTS["elevator_effectiveness"])
        x = [xi + 1e-3 * di for xi, di in zip(x, dx)]
        if k in (500, 1000, 2000):
            copy[k / 1000] = list(x)

    print("## aircraft.fmu, FMI 2.0 CoSimulation (internal forward Euler, h = 1e-3), "
          "elevator_rad=0.02 throttle=0.46 elevator_effectiveness=1")
    same = True
    for t in TIMES:
        r = row_at(cs, t)
        print(f"t={t}: " + " ".join(f"{n}={g17(r[n])}" for n in STATES))
        same &= all(float(r[n]) == c for n, c in zip(STATES, copy[t]))
    print(f"Python copy of the Euler arithmetic bit-identical at t = 0.5, 1, 2: {same}")
    print()
    print("## aircraft.fmu, FMI 2.0 ModelExchange, FMPy CVode, relative_tolerance=1e-10")
    for t in TIMES:
        r = row_at(me, t)
        print(f"t={t}: " + " ".join(f"{n}={g17(r[n])}" for n in STATES))
    print()
    print("## CS (Euler) - ME (CVode)")
    for t in TIMES:
        a, b = row_at(cs, t), row_at(me, t)
        print(f"t={t}: " + " ".join(f"{n}={float(a[n]) - float(b[n]):.3e}" for n in STATES))
    print()


def detector(out):
    fmu = os.path.join(out, "ewma_detector.fmu")
    start = {"in_1": 1.0, "in_2": -3.0, "in_3": 0.5}
    r = simulate_fmu(fmu, stop_time=0.1, output_interval=0.01, start_values=start,
                     output=["statistic", "isolated_channel"])
    lam = 0.05
    e = [0.0, 0.0, 0.0]
    same = True
    print("## ewma_detector.fmu, in_1=1 in_2=-3 in_3=0.5, lambda=0.05, means 0, scales 1, 10 steps of 0.01 s")
    for k in range(1, 11):
        e = [(1 - lam) * ei + lam * abs((u - 0.0) / 1.0) for ei, u in zip(e, start.values())]
        row = r[k]
        print(f"step {k:2d} (t={row['time']:.2f}): statistic={g17(row['statistic'])} "
              f"isolated_channel={int(row['isolated_channel'])}")
        same &= float(row["statistic"]) == max(e) and int(row["isolated_channel"]) == 2
    print(f"before the first step: statistic={g17(r[0]['statistic'])} isolated_channel={int(r[0]['isolated_channel'])}")
    print(f"Python copy bit-identical: {same}")
    print()


def trim(V=53.6):
    """Level flight (theta = alpha, q = 0) at V: solve dV = dalpha = dq = 0 for alpha, elevator, throttle."""
    def F(z):
        a, e, t = z
        return np.array(f([V, a, 0.0, a, 1000.0], e, t, 1.0)[:3])
    z = np.array([0.05, 0.0, 0.5])
    for _ in range(50):
        r = F(z)
        J = np.zeros((3, 3))
        for j in range(3):
            dz = np.zeros(3)
            dz[j] = 1e-7
            J[:, j] = (F(z + dz) - F(z - dz)) / 2e-7
        step = np.linalg.solve(J, r)
        z = z - step
        if np.max(np.abs(step)) < 1e-16:
            break
    return z, F(z)


def closed_loop(out, trim_z):
    """aircraft_cs.fmu + pitch_controller.fmu, 0.01 s steps: read the aircraft's outputs,
    set the controller's inputs, read its (direct-feedthrough) outputs, set the aircraft's
    inputs, doStep both."""
    def run(ac_start, ctl_start, cmd, t_end, label, report):
        fmus = {}
        for name, start in (("aircraft_cs", ac_start), ("pitch_controller", ctl_start)):
            path = os.path.join(out, name + ".fmu")
            md = read_model_description(path)
            unzipdir = unzip(path)
            s = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
            vr = {v.name: v.valueReference for v in md.modelVariables}
            s.instantiate()
            s.setupExperiment(startTime=0.0)
            for k, v in start.items():
                s.setReal([vr[k]], [v])
            s.enterInitializationMode()
            s.exitInitializationMode()
            fmus[name] = (s, vr)
        ac, avr = fmus["aircraft_cs"]
        ct, cvr = fmus["pitch_controller"]
        h = 0.01
        n = int(round(t_end / h))
        print(f"## closed loop, {label}")
        print("t      V_m_s        alpha_rad     q_rad_s       theta_rad     h_m          elevator_rad  throttle")
        for k in range(n + 1):
            t = k * h
            V, alpha, q, theta, hh = ac.getReal([avr[s] for s in STATES])
            ct.setReal([cvr["q_meas_rad_s"], cvr["theta_meas_rad"], cvr["V_meas_m_s"], cvr["elevator_cmd_rad"]],
                       [q, theta, V, cmd(t)])
            e, thr = ct.getReal([cvr["elevator_rad"], cvr["throttle"]])
            if any(abs(t - r) < 1e-9 for r in report):
                print(f"{t:5.1f}  {V:11.6f}  {alpha:12.8f}  {q:12.8f}  {theta:12.8f}  {hh:11.5f}  {e:12.8f}  {thr:10.7f}")
            if k == n:
                break
            ac.setReal([avr["elevator_rad"], avr["throttle"]], [e, thr])
            ac.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            ct.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        for s, _ in fmus.values():
            s.terminate()
            s.freeInstance()
        print()

    a, e, t = trim_z
    at_trim = {"V0_m_s": 53.6, "alpha0_rad": a, "theta0_rad": a, "q0_rad_s": 0.0}
    ctl_trim = {"elevator_trim_rad": e, "theta_ref_rad": a, "throttle_trim": t, "V_ref_m_s": 53.6,
                "theta_meas_rad": a, "V_meas_m_s": 53.6}
    run(at_trim, ctl_trim, lambda time: 0.02 if time >= 1.0 else 0.0, 60.0,
        "from the trim (controller trims = aircraft trim), elevator_cmd_rad = +0.02 from t = 1 s",
        [0, 1, 1.5, 2, 3, 5, 10, 20, 40, 60])
    run({}, {}, lambda time: 0.0, 120.0, "all FMU defaults (aircraft starts at alpha = theta = 0.05, not trimmed)",
        [0, 1, 2, 5, 10, 20, 40, 60, 90, 120])


def hooks(out):
    print("## fail_at_s / abort_at_s")
    path = os.path.join(out, "aircraft.fmu")
    md = read_model_description(path)
    unzipdir = unzip(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    # CS: doStep
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier="aircraft", instanceName="cs")
    s.instantiate()  # FMPy's default logger prints the FMU's messages
    s.setupExperiment(startTime=0.0)
    s.setReal([vr["fail_at_s"]], [1.0])
    s.enterInitializationMode()
    s.exitInitializationMode()
    t = 0.0
    status = 0
    for k in range(200):
        t = k * 0.01
        try:
            s.doStep(currentCommunicationPoint=t, communicationStepSize=0.01)
        except FMICallException as ex:
            status = ex.status
            break
    print(f"CS, fail_at_s=1: fmi2DoStep(t={t:.2f}) returned status {status} (3 = fmi2Error); the steps before returned 0 (fmi2OK)")
    s.freeInstance()
    # ME: getDerivatives
    m = FMU2Model(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier="aircraft", instanceName="me")
    m.instantiate()
    m.setupExperiment(startTime=0.0)
    m.setReal([vr["fail_at_s"]], [1.0])
    m.enterInitializationMode()
    m.exitInitializationMode()
    m.enterContinuousTimeMode()
    res = []
    for tt in (0.999, 1.0):
        m.setTime(tt)
        try:
            m.getDerivatives((c_double * 5)(), 5)
            res.append(0)
        except FMICallException as ex:
            res.append(ex.status)
    print(f"ME, fail_at_s=1: fmi2GetDerivatives status at t=0.999: {res[0]}, at t=1.0: {res[1]}")
    m.freeInstance()
    # abort: in a child process
    child = subprocess.run([sys.executable, __file__, "--abort-child", unzip(path)], capture_output=True, text=True)
    print(f"CS, abort_at_s=0.5, in a child process: return code {child.returncode} "
          f"(-6 = killed by SIGABRT); child printed: {child.stdout.strip()!r}")
    print()


def abort_child(unzipdir):
    r = simulate_fmu(unzipdir, stop_time=1.0, output_interval=0.01,
                     start_values={"abort_at_s": 0.5})
    print("not aborted, last t =", r["time"][-1])


def main():
    global _WORK
    if len(sys.argv) == 3 and sys.argv[1] == "--abort-child":
        abort_child(sys.argv[2])
        return
    _WORK = tempfile.TemporaryDirectory(prefix="fmpy-reference-")
    if len(sys.argv) > 1:
        out = os.path.abspath(sys.argv[1])
    else:
        out = os.path.join(_WORK.name, "fmus")
        build(out)
    aircraft_cs_me(out)
    detector(out)
    z, res = trim()
    print("## trim at V = 53.6 m/s, level flight (theta = alpha, q = 0), elevator_effectiveness = 1")
    print(f"alpha_rad = theta_rad = {z[0]:.12g}, elevator_rad = {z[1]:.12g}, throttle = {z[2]:.12g}")
    print(f"(17 digits: {float(z[0])!r}, {float(z[1])!r}, {float(z[2])!r}; residual dV, dalpha, dq = {res.tolist()})")
    print()
    closed_loop(out, z)
    hooks(out)


if __name__ == "__main__":
    main()
