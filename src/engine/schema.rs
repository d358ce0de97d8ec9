//! Column names of `trials.parquet` that several kinds of study share.

/// Column names shared by writer and statistics.
pub mod col {
    pub const TRIAL: &str = "trial";
    pub const DETECTOR: &str = "detector";
    pub const KIND: &str = "kind";
    pub const OUTPUT: &str = "output";
    pub const SIZE: &str = "size";
    pub const SIZE_BIN: &str = "size_bin";
    pub const ONSET_S: &str = "onset_s";
    pub const NOISE_SCALE: &str = "noise_scale";
    pub const NOISE_BIN: &str = "noise_bin";
    pub const PARAM_ERROR_BIN: &str = "param_error_bin";
    pub const DESIGN_ERROR: &str = "design_error";
    pub const DIVERGED_AT_S: &str = "diverged_at_s";
    pub const FALSE_ALARM_S: &str = "false_alarm_s";
    pub const FALSE_ALARM_OUTPUT: &str = "false_alarm_output";
    pub const ALARM_S: &str = "alarm_s";
    pub const ALARM_OUTPUT: &str = "alarm_output";
    pub const DELAY_S: &str = "delay_s";
    pub const ISOLATED_BY_MAX: &str = "isolated_by_max";
    pub const ISOLATED_BY_DIRECTION: &str = "isolated_by_direction";
    /// Fault kind of fault-free trials.
    pub const NO_FAULT: &str = "none";

    pub fn perr(name: &str) -> String {
        format!("perr_{name}")
    }
    pub fn pre_max(output: &str) -> String {
        format!("pre_max_{output}")
    }
    pub fn fp_t(output: &str) -> String {
        format!("fp_t_s_{output}")
    }
    pub fn fp_v(output: &str) -> String {
        format!("fp_v_{output}")
    }
}
