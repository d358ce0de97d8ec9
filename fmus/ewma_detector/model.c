/* SPDX-License-Identifier: MIT OR Apache-2.0 */
// Three-channel EWMA residual detector (FMI 2.0 Co-Simulation). At each fmi2DoStep,
// whatever its step size, with the inputs as set before the step:
//
//   e_i = (1 - lambda) * e_i + lambda * fabs((in_i - mean_i) / scale_i)    i = 1, 2, 3
//
// statistic = max(e_1, e_2, e_3); isolated_channel = index of the largest e_i (first on
// ties), 0 while all are 0. Outputs reflect the state after the latest doStep.

#include <math.h>  // fabs, NAN, INFINITY
#include <float.h> // DBL_MIN, DBL_MAX
#include "config.h"
#include "model.h"

#define DETECTOR_PARAMETERS(X) X(lambda) X(mean_1) X(mean_2) X(mean_3) X(scale_1) X(scale_2) X(scale_3)
#define DETECTOR_INPUTS(X) X(in_1) X(in_2) X(in_3)
#define DETECTOR_STATES(X) X(e_1) X(e_2) X(e_3)
#define DETECTOR_READABLE(X) DETECTOR_INPUTS(X) X(statistic) DETECTOR_PARAMETERS(X) DETECTOR_STATES(X)

// keep a time event pending at every internal step, so that eventUpdate() runs after each
static void requestEventAtEveryStep(ModelInstance *comp) {
    comp->nextEventTimeDefined = true;
    comp->nextEventTime        = -INFINITY;
}

Status setStartValues(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    M(in_1) = 0.0;
    M(in_2) = 0.0;
    M(in_3) = 0.0;

    M(lambda)  = 0.05;
    M(mean_1)  = 0.0;
    M(mean_2)  = 0.0;
    M(mean_3)  = 0.0;
    M(scale_1) = 1.0;
    M(scale_2) = 1.0;
    M(scale_3) = 1.0;

    M(e_1) = 0.0;
    M(e_2) = 0.0;
    M(e_3) = 0.0;

    M(last_update_at) = NAN;

    requestEventAtEveryStep(comp);

    comp->isDirtyValues = true;

    return OK;
}

Status calculateValues(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    double s = M(e_1);
    int channel = 1;
    if (M(e_2) > s) { s = M(e_2); channel = 2; }
    if (M(e_3) > s) { s = M(e_3); channel = 3; }

    M(statistic)        = s;
    M(isolated_channel) = (M(e_1) == 0.0 && M(e_2) == 0.0 && M(e_3) == 0.0) ? 0 : channel;

    comp->isDirtyValues = false;

    return OK;
}

Status getFloat64(ModelInstance* comp, ValueReference vr, double values[], size_t nValues, size_t* index) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(values);
    ASSERT_NOT_NULL2(index);

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
        DETECTOR_READABLE(GET_CASE)
        default:
            logError(comp, "Get Float64 is not allowed for value reference %u.", vr);
            return Error;
    }

#undef GET_CASE
}

Status getInt32(ModelInstance* comp, ValueReference vr, int32_t values[], size_t nValues, size_t* index) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(values);
    ASSERT_NOT_NULL2(index);

    if (comp->isDirtyValues) calculateValues(comp);

    switch (vr) {
        case vr_isolated_channel:
            ASSERT_NVALUES(1);
            values[(*index)++] = M(isolated_channel);
            return OK;
        default:
            logError(comp, "Get Int32 is not allowed for value reference %u.", vr);
            return Error;
    }
}

Status setFloat64(ModelInstance* comp, ValueReference vr, const double values[], size_t nValues, size_t* index) {
    ASSERT_NOT_NULL2(comp);
    ASSERT_NOT_NULL2(values);
    ASSERT_NOT_NULL2(index);

    const bool beforeInit = comp->state == Instantiated || comp->state == InitializationMode;

#define SET_INPUT_CASE(name) \
    case vr_##name: \
        ASSERT_NVALUES(1); \
        M(name) = values[(*index)++]; \
        break;

// parameters and initial states: before initialisation is finished only, with a range check
#define SET_CHECKED_CASE(name, lo, lo_text, hi) \
    case vr_##name: \
        ASSERT_NVALUES(1); \
        if (!beforeInit) { \
            logError(comp, "ewma_detector: " #name " can only be set before initialisation is finished."); \
            return Error; \
        } \
        if (!(values[*index] >= (lo) && values[*index] <= (hi))) { \
            logError(comp, "ewma_detector: " #name " = %.17g is out of range (must be " lo_text ")", values[*index]); \
            return Error; \
        } \
        M(name) = values[(*index)++]; \
        break;

    switch (vr) {
        DETECTOR_INPUTS(SET_INPUT_CASE)
        SET_CHECKED_CASE(lambda, DBL_MIN, "> 0 and <= 1", 1.0)
        SET_CHECKED_CASE(mean_1, -DBL_MAX, "finite", DBL_MAX)
        SET_CHECKED_CASE(mean_2, -DBL_MAX, "finite", DBL_MAX)
        SET_CHECKED_CASE(mean_3, -DBL_MAX, "finite", DBL_MAX)
        SET_CHECKED_CASE(scale_1, DBL_MIN, "> 0", INFINITY)
        SET_CHECKED_CASE(scale_2, DBL_MIN, "> 0", INFINITY)
        SET_CHECKED_CASE(scale_3, DBL_MIN, "> 0", INFINITY)
        SET_CHECKED_CASE(e_1, 0.0, ">= 0", INFINITY)
        SET_CHECKED_CASE(e_2, 0.0, ">= 0", INFINITY)
        SET_CHECKED_CASE(e_3, 0.0, ">= 0", INFINITY)
        default:
            logError(comp, "Set Float64 is not allowed for value reference %u.", vr);
            return Error;
    }

#undef SET_INPUT_CASE
#undef SET_CHECKED_CASE

    comp->isDirtyValues = true;

    return OK;
}

// Called after every internal step of fmi2DoStep (the pending time event). During a doStep
// comp->nextCommunicationPoint still holds the communication point the step began at, so a
// change of that value marks the first internal step of a new doStep.
Status eventUpdate(ModelInstance *comp) {
    ASSERT_NOT_NULL2(comp);

    if (comp->type == CoSimulation && !(comp->nextCommunicationPoint == M(last_update_at))) {
        const double lambda = M(lambda);
        M(e_1) = (1 - lambda) * M(e_1) + lambda * fabs((M(in_1) - M(mean_1)) / M(scale_1));
        M(e_2) = (1 - lambda) * M(e_2) + lambda * fabs((M(in_2) - M(mean_2)) / M(scale_2));
        M(e_3) = (1 - lambda) * M(e_3) + lambda * fabs((M(in_3) - M(mean_3)) / M(scale_3));
        M(last_update_at) = comp->nextCommunicationPoint;
        comp->isDirtyValues = true;
    }

    comp->valuesOfContinuousStatesChanged   = false;
    comp->nominalsOfContinuousStatesChanged = false;
    comp->terminateSimulation               = false;
    requestEventAtEveryStep(comp);

    return OK;
}
