/* SPDX-License-Identifier: MIT OR Apache-2.0 */
// Nonlinear longitudinal rigid aircraft (Navion-like light airplane) for the
// Reference-FMUs framework: FMI 2.0 ME + CS, FMI 3.0 ME + CS.
//
// The arithmetic in computeDerivatives() is written one operation at a time, in a fixed
// order, without fma or pow, so that a Rust copy can reproduce it bit for bit (build
// without -ffast-math and without FMA contraction, i.e. without -march=native).

#include <math.h>   // sin, cos
#include <stddef.h> // NULL
#include <stdlib.h> // abort
#include "config.h"
#include "model.h"

// parameters: settable in Instantiated and Initialization Mode only
#define AIRCRAFT_PARAMETERS(X) \
    X(m_kg) X(S_m2) X(cbar_m) X(Iyy_kg_m2) X(rho_kg_m3) X(g_m_s2) \
    X(CL0) X(CLa) X(CLa3) X(CLq) X(CLde) X(CD0) X(k_induced) \
    X(Cm0) X(Cma) X(Cma3) X(Cmq) X(Cmde) X(T_max_N) \
    X(V0_m_s) X(alpha0_rad) X(q0_rad_s) X(theta0_rad) X(h0_m) \
    X(fail_at_s) X(abort_at_s) X(segfault_at_s) X(diverge_at_s)

// inputs: settable at any time the FMI allows setting inputs
#define AIRCRAFT_INPUTS(X) X(elevator_rad) X(throttle) X(elevator_effectiveness)

// everything that can be read
#define AIRCRAFT_READABLE(X) \
    X(V_m_s) X(der_V_m_s) X(alpha_rad) X(der_alpha_rad) X(q_rad_s) X(der_q_rad_s) \
    X(theta_rad) X(der_theta_rad) X(h_m) X(der_h_m) X(gamma_rad) X(nz_g) \
    AIRCRAFT_INPUTS(X) AIRCRAFT_PARAMETERS(X)

Status setStartValues(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    M(elevator_rad)           = 0.0;
    M(throttle)               = 0.0;
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

    M(V0_m_s)     = 53.6;
    M(alpha0_rad) = 0.05;
    M(q0_rad_s)   = 0;
    M(theta0_rad) = 0.05;
    M(h0_m)       = 1000;

    M(fail_at_s)  = 1e30;
    M(abort_at_s) = 1e30;
    M(segfault_at_s) = 1e30;
    M(diverge_at_s)  = 1e30;

    M(V_m_s)     = M(V0_m_s);
    M(alpha_rad) = M(alpha0_rad);
    M(q_rad_s)   = M(q0_rad_s);
    M(theta_rad) = M(theta0_rad);
    M(h_m)       = M(h0_m);

    comp->isDirtyValues = true;

    return OK;
}

// The equations, in exactly this order and form.
static void computeDerivatives(ModelInstance *comp) {

    const double V     = M(V_m_s);
    const double alpha = M(alpha_rad);
    const double q     = M(q_rad_s);
    const double theta = M(theta_rad);

    const double qbar = 0.5 * M(rho_kg_m3) * V * V;
    const double qhat = q * M(cbar_m) / (2.0 * V);
    const double de   = M(elevator_effectiveness) * M(elevator_rad);

    const double CL = M(CL0) + M(CLa) * alpha - M(CLa3) * alpha * alpha * alpha + M(CLq) * qhat + M(CLde) * de;
    const double CD = M(CD0) + M(k_induced) * CL * CL;
    const double Cm = M(Cm0) + M(Cma) * alpha + M(Cma3) * alpha * alpha * alpha + M(Cmq) * qhat + M(Cmde) * de;

    const double L_N  = qbar * M(S_m2) * CL;
    const double D_N  = qbar * M(S_m2) * CD;
    const double M_Nm = qbar * M(S_m2) * M(cbar_m) * Cm;
    const double T_N  = M(T_max_N) * M(throttle);

    const double gamma = theta - alpha;

    M(der_V_m_s)     = (T_N * cos(alpha) - D_N) / M(m_kg) - M(g_m_s2) * sin(gamma);
    M(der_alpha_rad) = q - (T_N * sin(alpha) + L_N) / (M(m_kg) * V) + M(g_m_s2) * cos(gamma) / V;
    M(der_q_rad_s)   = M_Nm / M(Iyy_kg_m2);
    M(der_theta_rad) = q;
    M(der_h_m)       = V * sin(gamma);

    M(gamma_rad) = gamma;
    M(nz_g)      = L_N / (M(m_kg) * M(g_m_s2));
}

Status calculateValues(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    // Until Initialization Mode is exited the states follow the initial-state parameters,
    // so that setting V0_m_s etc. before or during initialisation works in ME and CS.
    // Every set marks the values dirty, and fmi[23]ExitInitializationMode calls this
    // function while still in Initialization Mode when they are.
    if (comp->state == Instantiated || comp->state == InitializationMode) {
        M(V_m_s)     = M(V0_m_s);
        M(alpha_rad) = M(alpha0_rad);
        M(q_rad_s)   = M(q0_rad_s);
        M(theta_rad) = M(theta0_rad);
        M(h_m)       = M(h0_m);
    }

    computeDerivatives(comp);

    comp->isDirtyValues = false;

    return OK;
}

#define UPDATE_IF_DIRTY() do { if (comp->isDirtyValues) calculateValues(comp); } while (0)

// Directional derivatives (fmi2GetDirectionalDerivative, FMI 3.0 likewise): the exact partial
// derivative of a derivative or output with respect to a state or input, by forward-mode
// differentiation of computeDerivatives() written out by hand (checked against dual numbers in
// tests/fmu.rs).
Status getPartialDerivative(ModelInstance *comp, ValueReference unknown, ValueReference known, double *partialDerivative) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(partialDerivative);

    UPDATE_IF_DIRTY();

    // The seed: 1 on the known variable, 0 elsewhere.
    double dV = 0, dalpha = 0, dq = 0, dtheta = 0, dh = 0, delevator = 0, dthrottle = 0, deffectiveness = 0;
    switch (known) {
        case vr_V_m_s:                  dV = 1; break;
        case vr_alpha_rad:              dalpha = 1; break;
        case vr_q_rad_s:                dq = 1; break;
        case vr_theta_rad:              dtheta = 1; break;
        case vr_h_m:                    dh = 1; break;
        case vr_elevator_rad:           delevator = 1; break;
        case vr_throttle:               dthrottle = 1; break;
        case vr_elevator_effectiveness: deffectiveness = 1; break;
        default:
            logError(comp, "aircraft: no partial derivative with respect to value reference %u (a state or an input).", known);
            return Error;
    }

    const double V = M(V_m_s), alpha = M(alpha_rad), q = M(q_rad_s), theta = M(theta_rad);
    const double m = M(m_kg), S = M(S_m2), cbar = M(cbar_m), g = M(g_m_s2);

    const double qbar = 0.5 * M(rho_kg_m3) * V * V;
    const double qhat = q * cbar / (2.0 * V);
    const double de   = M(elevator_effectiveness) * M(elevator_rad);
    const double CL = M(CL0) + M(CLa) * alpha - M(CLa3) * alpha * alpha * alpha + M(CLq) * qhat + M(CLde) * de;
    const double CD = M(CD0) + M(k_induced) * CL * CL;
    const double Cm = M(Cm0) + M(Cma) * alpha + M(Cma3) * alpha * alpha * alpha + M(Cmq) * qhat + M(Cmde) * de;
    const double L_N = qbar * S * CL;
    const double T_N = M(T_max_N) * M(throttle);
    const double gamma = theta - alpha;

    const double dqbar  = M(rho_kg_m3) * V * dV;
    const double dqhat  = cbar / (2.0 * V) * dq - q * cbar / (2.0 * V * V) * dV;
    const double dde    = M(elevator_effectiveness) * delevator + M(elevator_rad) * deffectiveness;
    const double dCL    = (M(CLa) - 3.0 * M(CLa3) * alpha * alpha) * dalpha + M(CLq) * dqhat + M(CLde) * dde;
    const double dCD    = 2.0 * M(k_induced) * CL * dCL;
    const double dCm    = (M(Cma) + 3.0 * M(Cma3) * alpha * alpha) * dalpha + M(Cmq) * dqhat + M(Cmde) * dde;
    const double dL     = dqbar * S * CL + qbar * S * dCL;
    const double dD     = dqbar * S * CD + qbar * S * dCD;
    const double dM     = S * cbar * (dqbar * Cm + qbar * dCm);
    const double dT     = M(T_max_N) * dthrottle;
    const double dgamma = dtheta - dalpha;

    double d;
    switch (unknown) {
        case vr_der_V_m_s:
            d = (dT * cos(alpha) - T_N * sin(alpha) * dalpha - dD) / m - g * cos(gamma) * dgamma;
            break;
        case vr_der_alpha_rad:
            d = dq - (dT * sin(alpha) + T_N * cos(alpha) * dalpha + dL) / (m * V)
                + (T_N * sin(alpha) + L_N) * dV / (m * V * V)
                - g * sin(gamma) * dgamma / V - g * cos(gamma) * dV / (V * V);
            break;
        case vr_der_q_rad_s:    d = dM / M(Iyy_kg_m2); break;
        case vr_der_theta_rad:  d = dq; break;
        case vr_der_h_m:        d = dV * sin(gamma) + V * cos(gamma) * dgamma; break;
        case vr_gamma_rad:      d = dgamma; break;
        case vr_nz_g:           d = dL / (m * g); break;
        case vr_V_m_s:          d = dV; break;
        case vr_alpha_rad:      d = dalpha; break;
        case vr_q_rad_s:        d = dq; break;
        case vr_theta_rad:      d = dtheta; break;
        case vr_h_m:            d = dh; break;
        default:
            logError(comp, "aircraft: no partial derivative of value reference %u (a derivative or an output).", unknown);
            return Error;
    }
    *partialDerivative = d;
    return OK;
}

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
        AIRCRAFT_READABLE(GET_CASE)
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
            logError(comp, "aircraft: parameter " #name " can only be set before initialisation is finished."); \
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
        AIRCRAFT_INPUTS(SET_INPUT_CASE)
        AIRCRAFT_PARAMETERS(SET_PARAMETER_CASE)
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

    x[0] = M(V_m_s);
    x[1] = M(alpha_rad);
    x[2] = M(q_rad_s);
    x[3] = M(theta_rad);
    x[4] = M(h_m);

    return OK;
}

Status getNominalsOfContinuousStates(ModelInstance* comp, double nominals[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(nominals);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    nominals[0] = 50.0;
    nominals[1] = 1.0;
    nominals[2] = 1.0;
    nominals[3] = 1.0;
    nominals[4] = 1000.0;

    return OK;
}

Status setContinuousStates(ModelInstance *comp, const double x[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(x);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    M(V_m_s)     = x[0];
    M(alpha_rad) = x[1];
    M(q_rad_s)   = x[2];
    M(theta_rad) = x[3];
    M(h_m)       = x[4];

    comp->isDirtyValues = true;

    return OK;
}

// Called by fmi[23]GetDerivatives (ME) and by every internal Euler step of
// fmi[23]DoStep (CS, through doFixedStep in cosimulation.c).
Status getDerivatives(ModelInstance *comp, double dx[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(dx);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    if (comp->time >= M(abort_at_s)) {
        logError(comp, "aircraft: aborting the process at t=%.17g as asked by abort_at_s", comp->time);
        abort();
    }

    if (comp->time >= M(segfault_at_s)) {
        logError(comp, "aircraft: writing through a null pointer at t=%.17g as asked by segfault_at_s", comp->time);
        *(volatile double *)NULL = comp->time;
    }

    if (comp->time >= M(fail_at_s)) {
        logError(comp, "aircraft: failing at t=%.17g as asked by fail_at_s", comp->time);
        return Error;
    }

    UPDATE_IF_DIRTY();

    dx[0] = M(der_V_m_s);
    dx[1] = M(der_alpha_rad);
    dx[2] = M(der_q_rad_s);
    dx[3] = M(der_theta_rad);
    dx[4] = M(der_h_m);

    // Test hook: an unstable pitch mode of 10/s from diverge_at_s on (der_q_rad_s, as read, keeps the
    // equations' value).
    if (comp->time >= M(diverge_at_s)) {
        dx[2] += 10.0 * (M(q_rad_s) + 0.01);
    }

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
