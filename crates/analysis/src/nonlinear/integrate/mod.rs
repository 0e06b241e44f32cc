//! Validated integration of a nonlinear plant over one control period.
