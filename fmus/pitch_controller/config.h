/* SPDX-License-Identifier: MIT OR Apache-2.0 */
#ifndef config_h
#define config_h

// Pitch-attitude / airspeed controller closing the loop around fmus/aircraft.
// Built on the Modelica Association's Reference-FMUs framework (fmus/include, fmus/src).

#define MODEL_IDENTIFIER pitch_controller
#define INSTANTIATION_TOKEN "{24368aa9-2f78-4091-95e5-64ad79dba05e}"

#define CO_SIMULATION

// z, the integral of the speed error, is the framework's one continuous state
#define MAX_CONTINUOUS_STATES 1

#define SET_FLOAT64

// The framework's fmi2DoStep always integrates with its own fixed-step forward Euler
// (cosimulation.c), FIXED_SOLVER_STEP at a time. With a step of 0.01 s a communication
// step of 0.01 s is exactly one Euler step, z = z + 0.01 * (V_ref - V_meas): the controller
// assumes 0.01 s communication steps (multiples of 0.01 s take several Euler steps; other
// step sizes are refused, see model.c).
#define FIXED_SOLVER_STEP 1e-2
#define DEFAULT_STOP_TIME 10

typedef enum {
    vr_time,
    vr_q_meas_rad_s, vr_theta_meas_rad, vr_V_meas_m_s, vr_elevator_cmd_rad,
    vr_elevator_rad, vr_throttle,
    vr_kq, vr_ktheta, vr_theta_ref_rad, vr_elevator_trim_rad, vr_kv, vr_ki_v, vr_V_ref_m_s, vr_throttle_trim,
    vr_z
} ValueReference;

typedef struct {

    // inputs
    double q_meas_rad_s;
    double theta_meas_rad;
    double V_meas_m_s;
    double elevator_cmd_rad;

    // outputs
    double elevator_rad;
    double throttle;

    // parameters
    double kq;
    double ktheta;
    double theta_ref_rad;
    double elevator_trim_rad;
    double kv;
    double ki_v;
    double V_ref_m_s;
    double throttle_trim;

    // continuous state: integral of V_ref - V_meas
    double z;

} ModelData;

#endif /* config_h */
