/* SPDX-License-Identifier: MIT OR Apache-2.0 */
// The nonlinear longitudinal aircraft of fmus/aircraft (same equations, same defaults) with a
// second-order elevator actuator, a first-order engine lag and first-order alpha / q / theta
// sensor lags: 11 continuous states, for the Reference-FMUs framework (FMI 2.0 ME + CS).
//
// The arithmetic in computeDerivatives() is written one operation at a time, in a fixed
// order, without fma or pow, so that a Rust copy (src/vehicles/actuated.rs) can reproduce it
// bit for bit (build without -ffast-math and without FMA contraction, i.e. without
// -march=native; the build uses -ffp-contract=off).

#include <math.h>   // sin, cos
#include <stdlib.h> // abort
#include "config.h"
#include "model.h"

// parameters: settable in Instantiated and Initialization Mode only
#define ACTUATED_PARAMETERS(X) \
    X(m_kg) X(S_m2) X(cbar_m) X(Iyy_kg_m2) X(rho_kg_m3) X(g_m_s2) \
    X(CL0) X(CLa) X(CLa3) X(CLq) X(CLde) X(CD0) X(k_induced) \
    X(Cm0) X(Cma) X(Cma3) X(Cmq) X(Cmde) X(T_max_N) \
    X(wa_rad_s) X(za) X(tau_engine_s) X(tau_sensor_s) \
    X(V0_m_s) X(alpha0_rad) X(q0_rad_s) X(theta0_rad) X(h0_m) \
    X(elevator0_rad) X(throttle0) \
    X(fail_at_s) X(abort_at_s)

// inputs: settable at any time the FMI allows setting inputs
#define ACTUATED_INPUTS(X) X(elevator_cmd_rad) X(throttle_cmd) X(elevator_effectiveness)

// everything that can be read
#define ACTUATED_READABLE(X) \
    X(V_m_s) X(der_V_m_s) X(alpha_rad) X(der_alpha_rad) X(q_rad_s) X(der_q_rad_s) \
    X(theta_rad) X(der_theta_rad) X(h_m) X(der_h_m) \
    X(elevator_rad) X(der_elevator_rad) X(elevator_rate_rad_s) X(der_elevator_rate_rad_s) \
    X(throttle_state) X(der_throttle_state) \
    X(alpha_meas_rad) X(der_alpha_meas_rad) X(q_meas_rad_s) X(der_q_meas_rad_s) \
    X(theta_meas_rad) X(der_theta_meas_rad) \
    X(gamma_rad) \
    ACTUATED_INPUTS(X) ACTUATED_PARAMETERS(X)

// The states follow their start parameters (the actuator rate starts at 0, the sensors at the
// aircraft's alpha0 / q0 / theta0).
static void statesFromStartValues(ModelInstance *comp) {
    M(V_m_s)               = M(V0_m_s);
    M(alpha_rad)           = M(alpha0_rad);
    M(q_rad_s)             = M(q0_rad_s);
    M(theta_rad)           = M(theta0_rad);
    M(h_m)                 = M(h0_m);
    M(elevator_rad)        = M(elevator0_rad);
    M(elevator_rate_rad_s) = 0.0;
    M(throttle_state)      = M(throttle0);
    M(alpha_meas_rad)      = M(alpha0_rad);
    M(q_meas_rad_s)        = M(q0_rad_s);
    M(theta_meas_rad)      = M(theta0_rad);
}

Status setStartValues(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    // commands start at the start positions, so that by default the actuator and the engine
    // stay where they start
    M(elevator_cmd_rad)       = 0.0211591440454;
    M(throttle_cmd)           = 0.459166130340;
    M(elevator_effectiveness) = 1.0;

    M(m_kg)      = 1247;
    M(S_m2)      = 17.09;
    M(cbar_m)    = 1.74;
    M(Iyy_kg_m2) = 4067.5;
    M(rho_kg_m3) = 1.225;
    M(g_m_s2)    = 9.80665;
    M(CL0)       = 0.2;
    M(CLa)       = 4.44;
    M(CLa3)      = 6.0;
    M(CLq)       = 3.8;
    M(CLde)      = 0.355;
    M(CD0)       = 0.05;
    M(k_induced) = 0.0675;
    M(Cm0)       = 0.05;
    M(Cma)       = -0.683;
    M(Cma3)      = -2.0;
    M(Cmq)       = -9.96;
    M(Cmde)      = -0.923;
    M(T_max_N)   = 4000;

    M(wa_rad_s)     = 40;
    M(za)           = 0.7;
    M(tau_engine_s) = 0.5;
    M(tau_sensor_s) = 0.02;

    M(V0_m_s)     = 53.6;
    M(alpha0_rad) = 0.05;
    M(q0_rad_s)   = 0;
    M(theta0_rad) = 0.05;
    M(h0_m)       = 1000;

    M(elevator0_rad) = 0.0211591440454;
    M(throttle0)     = 0.459166130340;

    M(fail_at_s)  = 1e30;
    M(abort_at_s) = 1e30;

    statesFromStartValues(comp);

    comp->isDirtyValues = true;

    return OK;
}

// The equations, in exactly this order and form. C evaluates a chain like a * b * c as
// (a * b) * c and a + b - c as (a + b) - c, left to right.
static void computeDerivatives(ModelInstance *comp) {

    const double V     = M(V_m_s);
    const double alpha = M(alpha_rad);
    const double q     = M(q_rad_s);
    const double theta = M(theta_rad);

    // --- the aircraft (fmus/aircraft/model.c, operation for operation), driven by the
    //     actuator position elevator_rad and the engine state throttle_state
    const double qbar = 0.5 * M(rho_kg_m3) * V * V;
    const double qhat = q * M(cbar_m) / (2.0 * V);
    const double de   = M(elevator_effectiveness) * M(elevator_rad);

    const double CL = M(CL0) + M(CLa) * alpha - M(CLa3) * alpha * alpha * alpha + M(CLq) * qhat + M(CLde) * de;
    const double CD = M(CD0) + M(k_induced) * CL * CL;
    const double Cm = M(Cm0) + M(Cma) * alpha + M(Cma3) * alpha * alpha * alpha + M(Cmq) * qhat + M(Cmde) * de;

    const double L_N  = qbar * M(S_m2) * CL;
    const double D_N  = qbar * M(S_m2) * CD;
    const double M_Nm = qbar * M(S_m2) * M(cbar_m) * Cm;
    const double T_N  = M(T_max_N) * M(throttle_state);

    const double gamma = theta - alpha;

    M(der_V_m_s)     = (T_N * cos(alpha) - D_N) / M(m_kg) - M(g_m_s2) * sin(gamma);
    M(der_alpha_rad) = q - (T_N * sin(alpha) + L_N) / (M(m_kg) * V) + M(g_m_s2) * cos(gamma) / V;
    M(der_q_rad_s)   = M_Nm / M(Iyy_kg_m2);
    M(der_theta_rad) = q;
    M(der_h_m)       = V * sin(gamma);

    // --- elevator actuator, second order, in this order:
    //   wa2      = wa_rad_s * wa_rad_s
    //   err      = elevator_cmd_rad - elevator_rad
    //   spring   = wa2 * err
    //   c1       = 2.0 * za
    //   c2       = c1 * wa_rad_s
    //   damping  = c2 * elevator_rate_rad_s
    //   der(elevator_rate_rad_s) = spring - damping
    //   der(elevator_rad)        = elevator_rate_rad_s
    const double wa2     = M(wa_rad_s) * M(wa_rad_s);
    const double err     = M(elevator_cmd_rad) - M(elevator_rad);
    const double spring  = wa2 * err;
    const double c1      = 2.0 * M(za);
    const double c2      = c1 * M(wa_rad_s);
    const double damping = c2 * M(elevator_rate_rad_s);
    M(der_elevator_rad)        = M(elevator_rate_rad_s);
    M(der_elevator_rate_rad_s) = spring - damping;

    // --- engine lag: der(throttle_state) = (throttle_cmd - throttle_state) / tau_engine_s
    //     (one subtraction, then one division)
    const double thr_err = M(throttle_cmd) - M(throttle_state);
    M(der_throttle_state) = thr_err / M(tau_engine_s);

    // --- sensor lags: der(x_meas) = (x - x_meas) / tau_sensor_s for x = alpha, q, theta
    //     (one subtraction, then one division)
    const double alpha_err = alpha - M(alpha_meas_rad);
    const double q_err     = q - M(q_meas_rad_s);
    const double theta_err = theta - M(theta_meas_rad);
    M(der_alpha_meas_rad) = alpha_err / M(tau_sensor_s);
    M(der_q_meas_rad_s)   = q_err / M(tau_sensor_s);
    M(der_theta_meas_rad) = theta_err / M(tau_sensor_s);

    M(gamma_rad) = gamma;
}

Status calculateValues(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    // Until Initialization Mode is exited the states follow the start parameters, so that
    // setting V0_m_s etc. before or during initialisation works in ME and CS. Every set
    // marks the values dirty, and fmi2ExitInitializationMode calls this function while
    // still in Initialization Mode when they are.
    if (comp->state == Instantiated || comp->state == InitializationMode) {
        statesFromStartValues(comp);
    }

    computeDerivatives(comp);

    comp->isDirtyValues = false;

    return OK;
}

#define UPDATE_IF_DIRTY() do { if (comp->isDirtyValues) calculateValues(comp); } while (0)

Status getFloat64(ModelInstance* comp, ValueReference vr, double values[], size_t nValues, size_t* index) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(values);
    ASSERT_NOT_NULL2(index);

    UPDATE_IF_DIRTY();

#define GET_CASE(name) \
    case vr_##name: \
        ASSERT_NVALUES(1); \
        values[(*index)++] = M(name); \
        return OK;

    switch (vr) {
        case vr_time:
            ASSERT_NVALUES(1);
            values[(*index)++] = comp->time;
            return OK;
        ACTUATED_READABLE(GET_CASE)
        default:
            logError(comp, "Get Float64 is not allowed for value reference %u.", vr);
            return Error;
    }

#undef GET_CASE
}

Status setFloat64(ModelInstance* comp, ValueReference vr, const double values[], size_t nValues, size_t* index) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(values);
    ASSERT_NOT_NULL2(index);

#define SET_PARAMETER_CASE(name) \
    case vr_##name: \
        if (comp->state != Instantiated && comp->state != InitializationMode) { \
            logError(comp, "aircraft_actuated: parameter " #name " can only be set before initialisation is finished."); \
            return Error; \
        } \
        ASSERT_NVALUES(1); \
        M(name) = values[(*index)++]; \
        break;

#define SET_INPUT_CASE(name) \
    case vr_##name: \
        ASSERT_NVALUES(1); \
        M(name) = values[(*index)++]; \
        break;

    switch (vr) {
        ACTUATED_INPUTS(SET_INPUT_CASE)
        ACTUATED_PARAMETERS(SET_PARAMETER_CASE)
        default:
            logError(comp, "Set Float64 is not allowed for value reference %u.", vr);
            return Error;
    }

#undef SET_PARAMETER_CASE
#undef SET_INPUT_CASE

    comp->isDirtyValues = true;

    return OK;
}

size_t getNumberOfContinuousStates(ModelInstance* comp) {
    UNUSED(comp);
    return MAX_CONTINUOUS_STATES;
}

Status getContinuousStates(ModelInstance *comp, double x[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(x);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    UPDATE_IF_DIRTY();

    x[0]  = M(V_m_s);
    x[1]  = M(alpha_rad);
    x[2]  = M(q_rad_s);
    x[3]  = M(theta_rad);
    x[4]  = M(h_m);
    x[5]  = M(elevator_rad);
    x[6]  = M(elevator_rate_rad_s);
    x[7]  = M(throttle_state);
    x[8]  = M(alpha_meas_rad);
    x[9]  = M(q_meas_rad_s);
    x[10] = M(theta_meas_rad);

    return OK;
}

Status getNominalsOfContinuousStates(ModelInstance* comp, double nominals[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(nominals);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    nominals[0]  = 50.0;
    nominals[1]  = 1.0;
    nominals[2]  = 1.0;
    nominals[3]  = 1.0;
    nominals[4]  = 1000.0;
    nominals[5]  = 1.0;
    nominals[6]  = 1.0;
    nominals[7]  = 1.0;
    nominals[8]  = 1.0;
    nominals[9]  = 1.0;
    nominals[10] = 1.0;

    return OK;
}

Status setContinuousStates(ModelInstance *comp, const double x[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(x);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    M(V_m_s)               = x[0];
    M(alpha_rad)           = x[1];
    M(q_rad_s)             = x[2];
    M(theta_rad)           = x[3];
    M(h_m)                 = x[4];
    M(elevator_rad)        = x[5];
    M(elevator_rate_rad_s) = x[6];
    M(throttle_state)      = x[7];
    M(alpha_meas_rad)      = x[8];
    M(q_meas_rad_s)        = x[9];
    M(theta_meas_rad)      = x[10];

    comp->isDirtyValues = true;

    return OK;
}

// Called by fmi2GetDerivatives (ME) and by every internal Euler step of fmi2DoStep (CS,
// through doFixedStep in cosimulation.c).
Status getDerivatives(ModelInstance *comp, double dx[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(dx);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    if (comp->time >= M(abort_at_s)) {
        logError(comp, "aircraft_actuated: aborting the process at t=%.17g as asked by abort_at_s", comp->time);
        abort();
    }

    if (comp->time >= M(fail_at_s)) {
        logError(comp, "aircraft_actuated: failing at t=%.17g as asked by fail_at_s", comp->time);
        return Error;
    }

    UPDATE_IF_DIRTY();

    dx[0]  = M(der_V_m_s);
    dx[1]  = M(der_alpha_rad);
    dx[2]  = M(der_q_rad_s);
    dx[3]  = M(der_theta_rad);
    dx[4]  = M(der_h_m);
    dx[5]  = M(der_elevator_rad);
    dx[6]  = M(der_elevator_rate_rad_s);
    dx[7]  = M(der_throttle_state);
    dx[8]  = M(der_alpha_meas_rad);
    dx[9]  = M(der_q_meas_rad_s);
    dx[10] = M(der_theta_meas_rad);

    return OK;
}

Status eventUpdate(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    comp->valuesOfContinuousStatesChanged   = false;
    comp->nominalsOfContinuousStatesChanged = false;
    comp->terminateSimulation               = false;
    comp->nextEventTimeDefined              = false;

    return OK;
}
