/* SPDX-License-Identifier: MIT OR Apache-2.0 */
#ifndef config_h
#define config_h

// Nonlinear longitudinal rigid aircraft (Navion-like light airplane).
// Built on the Modelica Association's Reference-FMUs framework (fmus/include, fmus/src).

#define MODEL_IDENTIFIER aircraft
#define INSTANTIATION_TOKEN "{71e99bc9-e656-419f-923e-b53a44f8ec57}"

#define CO_SIMULATION
#define MODEL_EXCHANGE

#define MAX_CONTINUOUS_STATES 5

#define SET_FLOAT64
#define GET_PARTIAL_DERIVATIVE

// forward Euler step of the framework's fixed-step co-simulation solver (cosimulation.c)
#define FIXED_SOLVER_STEP 1e-3
#define DEFAULT_STOP_TIME 10

// value references: the order here is the order of the variables in FMI2.xml / FMI3.xml
typedef enum {
    vr_time,
    vr_V_m_s, vr_der_V_m_s,
    vr_alpha_rad, vr_der_alpha_rad,
    vr_q_rad_s, vr_der_q_rad_s,
    vr_theta_rad, vr_der_theta_rad,
    vr_h_m, vr_der_h_m,
    vr_gamma_rad, vr_nz_g,
    vr_elevator_rad, vr_throttle, vr_elevator_effectiveness,
    vr_m_kg, vr_S_m2, vr_cbar_m, vr_Iyy_kg_m2, vr_rho_kg_m3, vr_g_m_s2,
    vr_CL0, vr_CLa, vr_CLa3, vr_CLq, vr_CLde, vr_CD0, vr_k_induced,
    vr_Cm0, vr_Cma, vr_Cma3, vr_Cmq, vr_Cmde, vr_T_max_N,
    vr_V0_m_s, vr_alpha0_rad, vr_q0_rad_s, vr_theta0_rad, vr_h0_m,
    vr_fail_at_s, vr_abort_at_s, vr_segfault_at_s, vr_diverge_at_s
} ValueReference;

typedef struct {

    // continuous states x[0..5]
    double V_m_s;
    double alpha_rad;
    double q_rad_s;
    double theta_rad;
    double h_m;

    // their derivatives
    double der_V_m_s;
    double der_alpha_rad;
    double der_q_rad_s;
    double der_theta_rad;
    double der_h_m;

    // other outputs
    double gamma_rad;
    double nz_g;

    // inputs
    double elevator_rad;
    double throttle;
    double elevator_effectiveness;

    // parameters
    double m_kg;
    double S_m2;
    double cbar_m;
    double Iyy_kg_m2;
    double rho_kg_m3;
    double g_m_s2;
    double CL0;
    double CLa;
    double CLa3;
    double CLq;
    double CLde;
    double CD0;
    double k_induced;
    double Cm0;
    double Cma;
    double Cma3;
    double Cmq;
    double Cmde;
    double T_max_N;
    double V0_m_s;
    double alpha0_rad;
    double q0_rad_s;
    double theta0_rad;
    double h0_m;
    double fail_at_s;
    double abort_at_s;
    double segfault_at_s;
    double diverge_at_s;

} ModelData;

#endif /* config_h */
