//! The `mechanism!` macro of vigp.
