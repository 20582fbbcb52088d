//! Writes the forced learned-model fixture of `tests/learn/embedded_learned.rs`
//! the way a user of an actuated mechanism would: train a learned model
//! with inputs in Rust (`Learned::train_forced`; `vigp fit` does the same
//! from a CSV with `u_<joint>` columns), save it as JSON, and export it with `vigp export`
//! (through `vigp::cli`, the tool that `vigp::cli::main::<M>()` gives a
//! mechanism of one's own).
//!
//! ```text
//! cargo run --release --features cli --example learned_forced_fixture [-- DIR]
//! ```
//!
//! `DIR` defaults to `tests/fixtures`; it receives
//! `learned_drive_cartpole.json` and `learned_drive_cartpole.rs`. The data:
//! a cart-pole with 10 % heavier links and more rail friction than the
//! nominal `DriveCartpole`, pushed by piecewise-constant forces U[−3, 3] N
//! held 10 steps, first-order VI at Δt = 10 ms, 3 runs of 40 steps (every
//! second transition kept: N = 59). Seeded: the same build writes the same
//! files. `bash scripts/learned_fixture.sh` runs it.

use std::error::Error;
use std::path::PathBuf;

use nalgebra::SVector;
use vigp::gp::TrainOptions;
use vigp::learned::{Encoding, Learned, Prior, forced_transitions};
use vigp::prelude::*;

#[path = "../tests/common/drive_cartpole.rs"]
mod drive_cartpole;
use drive_cartpole::DriveCartpole;

const DT: f64 = 0.01;

#[path = "../tests/common/rng.rs"]
mod rng;
use rng::Rng;

fn main() -> Result<(), Box<dyn Error>> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "tests/fixtures".into()),
    );
    let mut truth = DriveCartpole::default();
    truth.links.cart.mass *= 1.1;
    truth.links.pole.mass *= 1.1;
    truth.joints.rail.damping = 0.4;
    let vi = Variational::new(truth.minimal(), DT)?;
    let mut rng = Rng(42);
    let mut data = Vec::new();
    for _ in 0..3 {
        let mut z = State::new([rng.uniform(-0.2, 0.2), rng.uniform(-0.6, 0.6)], [0.0, 0.0]);
        let mut positions = vec![z.q];
        let mut logged = vec![SVector::<f64, 1>::zeros()];
        let mut u = SVector::<f64, 1>::zeros();
        for k in 0..40 {
            if k % 10 == 0 {
                u = SVector::from([rng.uniform(-3.0, 3.0)]);
            }
            z = vi.step_forced(&z, &u)?;
            positions.push(z.q);
            logged.push(u);
        }
        data.extend(forced_transitions(&positions, &logged, DT));
    }
    let data: Vec<_> = data.into_iter().step_by(2).collect();
    let options = TrainOptions {
        restarts: 1,
        seed: 7,
        ..TrainOptions::default()
    };
    let (l, _) = Learned::train_forced(
        DriveCartpole::default().minimal(),
        DT,
        &data,
        Encoding::SinCos,
        Prior::Nominal,
        &options,
    )?;
    std::fs::create_dir_all(&dir)?;
    let json = dir.join("learned_drive_cartpole.json");
    let rs = dir.join("learned_drive_cartpole.rs");
    l.save(&json)?;
    println!("wrote {} ({} transitions)", json.display(), data.len());
    let tool = [vigp::cli::system::<DriveCartpole>()];
    let mut out = Vec::new();
    vigp::cli::run(
        &tool,
        [
            "vigp",
            "export",
            "--model",
            json.to_str().ok_or("non-UTF-8 path")?,
            "--out",
            rs.to_str().ok_or("non-UTF-8 path")?,
        ],
        &mut out,
    )?;
    print!("{}", String::from_utf8(out)?);
    Ok(())
}
