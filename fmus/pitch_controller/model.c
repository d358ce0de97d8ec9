/* SPDX-License-Identifier: MIT OR Apache-2.0 */
// Pitch-attitude / airspeed controller for fmus/aircraft (FMI 2.0 Co-Simulation):
//
//   elevator = elevator_trim + elevator_cmd - kq * q_meas - ktheta * (theta_meas - theta_ref)
//   throttle = clamp(throttle_trim + kv * (V_ref - V_meas) + ki_v * z, 0, 1)
//   z        = z + (V_ref - V_meas) * h   (forward Euler over each 0.01 s communication step)
//
// Positive elevator pitches the aircraft nose down (Cmde < 0), so the stabilising pitch
// gains kq and ktheta are negative.

#include "config.h"
#include "model.h"

#define CONTROLLER_PARAMETERS(X) \
    X(kq) X(ktheta) X(theta_ref_rad) X(elevator_trim_rad) X(kv) X(ki_v) X(V_ref_m_s) X(throttle_trim)

#define CONTROLLER_INPUTS(X) X(q_meas_rad_s) X(theta_meas_rad) X(V_meas_m_s) X(elevator_cmd_rad)

#define CONTROLLER_READABLE(X) CONTROLLER_INPUTS(X) X(elevator_rad) X(throttle) CONTROLLER_PARAMETERS(X) X(z)

// The framework's absolute tolerance for "the same time" (isClose in cosimulation.c).
#define TIME_EPSILON 1e-5

Status setStartValues(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    M(q_meas_rad_s)     = 0.0;
    M(theta_meas_rad)   = 0.05;
    M(V_meas_m_s)       = 53.6;
    M(elevator_cmd_rad) = 0.0;

    M(kq)                = -0.5;
    M(ktheta)            = -2.0;
    M(theta_ref_rad)     = 0.05;
    M(elevator_trim_rad) = 0.0;
    M(kv)                = 0.05;
    M(ki_v)              = 0.01;
    M(V_ref_m_s)         = 53.6;
    M(throttle_trim)     = 0.46;

    M(z) = 0.0;

    comp->isDirtyValues = true;

    return OK;
}

Status calculateValues(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    M(elevator_rad) = M(elevator_trim_rad) + M(elevator_cmd_rad) - M(kq) * M(q_meas_rad_s)
                    - M(ktheta) * (M(theta_meas_rad) - M(theta_ref_rad));

    double throttle = M(throttle_trim) + M(kv) * (M(V_ref_m_s) - M(V_meas_m_s)) + M(ki_v) * M(z);
    if (throttle < 0.0) throttle = 0.0;
    if (throttle > 1.0) throttle = 1.0;
    M(throttle) = throttle;

    comp->isDirtyValues = false;

    return OK;
}

// After a communication step that is not a multiple of FIXED_SOLVER_STEP the framework's
// time lags behind the communication point: refuse, rather than integrate z wrongly.
static Status checkStepSize(ModelInstance *comp) {
    if (comp->type == CoSimulation && comp->state != Instantiated && comp->state != InitializationMode &&
        comp->time < comp->nextCommunicationPoint - TIME_EPSILON) {
        logError(comp, "pitch_controller: communication steps must be multiples of %g s "
            "(internal time %.17g, communication point %.17g)",
            FIXED_SOLVER_STEP, comp->time, comp->nextCommunicationPoint);
        return Error;
    }
    return OK;
}

Status getFloat64(ModelInstance* comp, ValueReference vr, double values[], size_t nValues, size_t* index) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(values);
    ASSERT_NOT_NULL2(index);

    if (checkStepSize(comp) != OK) return Error;

    if (comp->isDirtyValues) calculateValues(comp);

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
        CONTROLLER_READABLE(GET_CASE)
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
            logError(comp, "pitch_controller: " #name " can only be set before initialisation is finished."); \
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
        CONTROLLER_INPUTS(SET_INPUT_CASE)
        CONTROLLER_PARAMETERS(SET_PARAMETER_CASE)
        SET_PARAMETER_CASE(z) // initial value of the integrator
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

    x[0] = M(z);

    return OK;
}

Status getNominalsOfContinuousStates(ModelInstance* comp, double nominals[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(nominals);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    nominals[0] = 1.0;

    return OK;
}

Status setContinuousStates(ModelInstance *comp, const double x[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(x);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    M(z) = x[0];

    comp->isDirtyValues = true;

    return OK;
}

// Called once per internal Euler step of fmi2DoStep: with FIXED_SOLVER_STEP = 0.01 the
// update is z + 0.01 * (V_ref - V_meas), bit for bit z + (V_ref - V_meas) * h for h = 0.01.
Status getDerivatives(ModelInstance *comp, double dx[], size_t nx) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(dx);
    ASSERT_SIZE_T(nx, MAX_CONTINUOUS_STATES);

    if (checkStepSize(comp) != OK) return Error;

    dx[0] = M(V_ref_m_s) - M(V_meas_m_s);

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
