//! Gaussian-process regression (exact ARD GP trained by marginal likelihood).
