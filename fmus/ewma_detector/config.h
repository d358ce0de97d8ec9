/* SPDX-License-Identifier: MIT OR Apache-2.0 */
#ifndef config_h
#define config_h

// Three-channel EWMA residual detector (FMI 2.0 Co-Simulation).
// Built on the Modelica Association's Reference-FMUs framework (fmus/include, fmus/src).

#define MODEL_IDENTIFIER ewma_detector
#define INSTANTIATION_TOKEN "{9d486e1a-daea-4849-bb96-2d21b4ba2b26}"

#define CO_SIMULATION

#define GET_INT32
#define SET_FLOAT64

// The EWMA update runs once per fmi2DoStep, whatever its step size. The framework's
// fmi2DoStep only calls into the model through its fixed-step loop, so the model keeps a
// time event pending at every internal step (eventUpdate) and updates on the first internal
// step of each new communication step. A communication step must therefore contain at least
// one internal step: step sizes >= FIXED_SOLVER_STEP.
#define EVENT_UPDATE
#define FIXED_SOLVER_STEP 1e-4
#define DEFAULT_STOP_TIME 10

typedef enum {
    vr_time,
    vr_in_1, vr_in_2, vr_in_3,
    vr_statistic, vr_isolated_channel,
    vr_lambda, vr_mean_1, vr_mean_2, vr_mean_3, vr_scale_1, vr_scale_2, vr_scale_3,
    vr_e_1, vr_e_2, vr_e_3
} ValueReference;

typedef struct {

    // inputs
    double in_1;
    double in_2;
    double in_3;

    // outputs
    double statistic;
    int isolated_channel;

    // parameters
    double lambda;
    double mean_1;
    double mean_2;
    double mean_3;
    double scale_1;
    double scale_2;
    double scale_3;

    // discrete states
    double e_1;
    double e_2;
    double e_3;

    // the communication point at which the latest doStep began (NaN before the first)
    double last_update_at;

} ModelData;

#endif /* config_h */
