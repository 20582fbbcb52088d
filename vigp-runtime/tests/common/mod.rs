//! Helpers shared by the integration tests of vigp-runtime (`mod common;`).

use vigp_runtime::identify::{Log, Transition};

/// The transition of `log` around sample `k`: the positions at k − 1, k and
/// k + 1, the inputs at k − 1 and k.
pub fn transition_at(log: &Log, k: usize) -> Transition<'_> {
    Transition {
        positions: [
            &log.positions[k - 1],
            &log.positions[k],
            &log.positions[k + 1],
        ],
        inputs: [&log.inputs[k - 1], &log.inputs[k]],
    }
}
