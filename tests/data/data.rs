//! `vigp::data`: every case of a measured-trajectory CSV file, each a clear
//! error or handled as documented.

use std::f64::consts::PI;
use vigp::data::{DataError, Dataset, ReadOptions};
use vigp::learned::transitions;
use vigp::systems::{CartpoleMinimal, PendulumMinimal};
use vigp::{CoordinateKind, SVector};

fn read2(text: &str) -> Result<Dataset<2>, DataError> {
    Dataset::read_for::<CartpoleMinimal, 0, _>(text.as_bytes(), &ReadOptions::default())
}

fn read1(text: &str, opts: &ReadOptions) -> Result<Dataset<1>, DataError> {
    Dataset::read_for::<PendulumMinimal, 0, _>(text.as_bytes(), opts)
}

#[test]
fn runs_split_columns_in_any_order_and_transitions_match() {
    let text = "t,hinge,run,rail\n\
                0.00,0.10,a,1.0\n0.01,0.11,a,1.1\n0.02,0.13,a,1.3\n0.03,0.16,a,1.6\n\
                5.00,-0.2,b,0.0\n5.01,-0.2,b,0.5\n5.02,-0.1,b,0.75\n";
    let d = read2(text).unwrap();
    assert_eq!(d.runs.len(), 2);
    assert_eq!(
        (d.runs[0].name.as_str(), d.runs[1].name.as_str()),
        ("a", "b")
    );
    assert_eq!(d.runs[1].t0, 5.0);
    assert_eq!(d.runs[1].line, 6);
    // columns are mapped by name: rail first, hinge second
    assert_eq!(d.runs[0].positions[1], SVector::from([1.1, 0.11]));
    let dt = d.dt(1e-9).unwrap();
    // the mean step of decimal timestamps, without binary rounding noise
    assert_eq!(dt, 0.01);
    let tr = d.transitions();
    // 4 rows give 2 transitions, 3 rows give 1
    assert_eq!(tr.len(), 3);
    let expect = transitions(&d.runs[0].positions, d.runs[0].dt.unwrap());
    assert_eq!(&tr[..2], &expect[..]);
    // v_k = (x_{k+1} − x_k)/Δt with the run's Δt: (1.3 − 1.1)/0.01 = 20
    assert!((tr[1].z.v[0] - 20.0).abs() < 1e-9, "{:?}", tr[1]);
    assert!((tr[1].v_next[0] - 30.0).abs() < 1e-9, "{:?}", tr[1]);
    let z = d.runs[1].state(0).unwrap();
    assert!((z.v[0] - 50.0).abs() < 1e-9);
}

/// A pendulum spinning at 5 rad/s logged by a sensor reporting (−π, π]:
/// unwrapped back to the true angle (to rounding), so velocities stay
/// 5 rad/s instead of jumping by 2π/Δt ≈ 628 rad/s.
#[test]
fn wrapped_angles_are_unwrapped() {
    let mut text = String::from("run,t,pivot\n");
    let truth: Vec<f64> = (0..300).map(|k| 2.0 + 5.0 * k as f64 * 0.01).collect();
    for (k, th) in truth.iter().enumerate() {
        let wrapped = (th + PI).rem_euclid(2.0 * PI) - PI;
        text.push_str(&format!("spin,{},{wrapped}\n", k as f64 * 0.01));
    }
    let d = read1(&text, &ReadOptions::default()).unwrap();
    for (p, t) in d.runs[0].positions.iter().zip(&truth) {
        assert!((p[0] - t).abs() < 1e-12, "{} vs {t}", p[0]);
    }
    let vmax = d
        .transitions()
        .iter()
        .map(|t| t.v_next[0].abs())
        .fold(0.0, f64::max);
    assert!((vmax - 5.0).abs() < 1e-9, "{vmax}");
    // without unwrapping the wraps show up as ≈ 2π/Δt jumps
    let raw = read1(
        &text,
        &ReadOptions {
            unwrap_angles: false,
            ..Default::default()
        },
    )
    .unwrap();
    let vmax = raw
        .transitions()
        .iter()
        .map(|t| t.v_next[0].abs())
        .fold(0.0, f64::max);
    assert!(vmax > 600.0, "{vmax}");
    // lengths are never unwrapped: a cart jumping by 4 m stays a jump
    let d = read2("run,t,rail,hinge\na,0,0,0\na,0.01,4,0\na,0.02,8,0\n").unwrap();
    assert_eq!(d.runs[0].positions[2][0], 8.0);
}

#[test]
fn uneven_time_is_an_error_naming_run_and_line_unless_resampling_is_asked() {
    let text = "run,t,pivot\nr1,0,0\nr1,0.01,0.01\nr1,0.02,0.02\nr2,0,0\nr2,0.01,0.01\nr2,0.025,0.025\nr2,0.03,0.03\n";
    let e = read1(text, &ReadOptions::default()).unwrap_err();
    match &e {
        DataError::NonUniformTime { run, line, .. } => {
            assert_eq!((run.as_str(), *line), ("r2", 7));
        }
        other => panic!("{other:?}"),
    }
    assert!(e.to_string().contains("run `r2`, line 7"), "{e}");
    // resampling onto 0.01 s: linear motion is reproduced exactly
    let opts = ReadOptions {
        resample: Some(0.01),
        ..Default::default()
    };
    let d = read1(text, &opts).unwrap();
    assert_eq!(d.runs[1].positions.len(), 4);
    for (k, p) in d.runs[1].positions.iter().enumerate() {
        assert!((p[0] - 0.01 * k as f64).abs() < 1e-15, "{k}: {}", p[0]);
    }
    assert_eq!(d.runs[1].dt, Some(0.01));
    // a step far below the sampling is refused, not allocated (1e-9 s on
    // this 0.03 s run would be 3·10⁷ samples; it used to abort the process
    // on 10 ms data of a few seconds)
    for dt in [1e-9, 1e-300] {
        let tiny = ReadOptions {
            resample: Some(dt),
            ..Default::default()
        };
        let e = read1(text, &tiny).unwrap_err();
        assert!(matches!(e, DataError::InvalidOption { .. }), "{e}");
    }
    // time going backwards is an error even when resampling
    let e = read1("run,t,pivot\na,0,0\na,0.01,0\na,0.005,0\n", &opts).unwrap_err();
    assert!(
        matches!(e, DataError::TimeNotIncreasing { line: 4, .. }),
        "{e}"
    );
    // a 300 Hz log with timestamps rounded to 6 or 4 decimals (steps off
    // by up to 1e-6 s = 3e-4 of Δt, or 1e-4 s = 3e-2 of Δt) passes: the
    // check allows the printed rounding on top of the tolerance (1e-3 of
    // Δt). One step 1 % long, printed to 6 decimals, does not.
    for (decimals, late) in [(6, 0.0), (4, 0.0), (6, 0.01)] {
        let mut text = String::from("run,t,pivot\n");
        for k in 0..50 {
            let t = (k as f64 + if k >= 30 { late } else { 0.0 }) / 300.0;
            text.push_str(&format!("a,{:.*},0\n", decimals, t));
        }
        let read = read1(&text, &ReadOptions::default());
        if late == 0.0 {
            let dt = read.unwrap().runs[0].dt.unwrap();
            assert!((dt - 1.0 / 300.0).abs() < 1e-4 / 49.0, "{decimals}: {dt}");
        } else {
            // row k = 30 (line 32) ends the long step
            assert!(
                matches!(read, Err(DataError::NonUniformTime { line: 32, .. })),
                "{read:?}"
            );
        }
    }
    // runs with different steps are caught when a common step is needed
    let d = read1(
        "run,t,pivot\na,0,0\na,0.01,0\nb,0,0\nb,0.02,0\n",
        &ReadOptions::default(),
    )
    .unwrap();
    assert!(matches!(
        d.dt(1e-6),
        Err(DataError::TimeStepMismatch { .. })
    ));
    assert!(
        matches!(d.check_dt(0.01, 1e-6), Err(DataError::TimeStepMismatch { run, .. }) if run == "b")
    );
}

#[test]
fn missing_extra_and_duplicate_columns() {
    let e = read2("run,t,rail\na,0,0\n").unwrap_err();
    assert!(
        matches!(&e, DataError::MissingColumn { name, .. } if name == "hinge"),
        "{e}"
    );
    let e = read2("run,rail,hinge\na,0,0\n").unwrap_err();
    assert!(
        matches!(&e, DataError::MissingColumn { name, .. } if name == "t"),
        "{e}"
    );
    let e = read2("run,t,rail,hinge,speed\na,0,0,0,1\n").unwrap_err();
    assert!(
        matches!(&e, DataError::UnknownColumn { name, column: 5, .. } if name == "speed"),
        "{e}"
    );
    let e = read2("run,t,rail,hinge,u_rail\na,0,0,0,1\n").unwrap_err();
    assert!(
        e.to_string()
            .contains("the mechanism has no `actuated` joint"),
        "{e}"
    );
    let e = read2("run,t,rail,hinge,\na,0,0,0,\n").unwrap_err();
    assert!(e.to_string().contains("trailing comma"), "{e}");
    let e = read2("run,t,rail,hinge,rail\na,0,0,0,0\n").unwrap_err();
    assert!(
        matches!(
            e,
            DataError::DuplicateColumn {
                first: 3,
                second: 5,
                ..
            }
        ),
        "{e}"
    );
    // a row with a value missing (fewer fields than the header)
    let e = read2("run,t,rail,hinge\na,0,0,0\na,0.01,0\n").unwrap_err();
    assert!(matches!(e, DataError::Csv { line: 3, .. }), "{e}");
    // a row with an extra field
    let e = read2("run,t,rail,hinge\na,0,0,0\na,0.01,0,0,7\n").unwrap_err();
    assert!(matches!(e, DataError::Csv { line: 3, .. }), "{e}");
    // an empty value
    let e = read2("run,t,rail,hinge\na,0,0,0\na,0.01,,0\n").unwrap_err();
    assert!(
        matches!(&e, DataError::Parse { line: 3, column, .. } if column == "rail"),
        "{e}"
    );
    let e = read2("run,t,rail,hinge\na,0,zero,0\n").unwrap_err();
    assert!(e.to_string().contains("line 2, column `rail`"), "{e}");
}

#[test]
fn nan_and_infinity_are_rejected_with_line_and_column() {
    for (bad, col) in [("NaN", "hinge"), ("inf", "hinge"), ("-infinity", "hinge")] {
        let text = format!("run,t,rail,hinge\na,0,0,0\na,0.01,0,{bad}\n");
        let e = read2(&text).unwrap_err();
        assert!(
            matches!(&e, DataError::NonFinite { line: 3, column, .. } if column == col),
            "{bad}: {e}"
        );
    }
    let e = read2("run,t,rail,hinge\na,NaN,0,0\n").unwrap_err();
    assert!(
        matches!(&e, DataError::NonFinite { line: 2, column, .. } if column == "t"),
        "{e}"
    );
    // a number beyond f64's range reads as ∞: the message says so
    let e = read2("run,t,rail,hinge\na,0,1e400,0\n").unwrap_err();
    assert!(
        matches!(&e, DataError::NonFinite { line: 2, column, .. } if column == "rail"),
        "{e}"
    );
    assert!(e.to_string().contains("beyond ±1.8e308"), "{e}");
}

/// Finite readings can still overflow what is made of them: an angle
/// unwrapped across readings ±1e308 apart, a velocity (x_{k+1} − x_k)/Δt,
/// a time step 5e-324. Each is an error naming where, never a NaN or ±∞
/// handed on (the old reader returned positions [1e308, NaN, NaN]).
#[test]
fn finite_readings_that_overflow_are_errors() {
    let e = read2("run,t,rail,hinge\na,0,0,1e308\na,0.01,0,-1e308\na,0.02,0,1e308\n").unwrap_err();
    assert!(
        matches!(&e, DataError::Overflow { line: 3, column, .. } if column == "hinge"),
        "{e}"
    );
    assert!(e.to_string().contains("line 3, column `hinge`"), "{e}");
    // a length is not unwrapped: its velocity overflows
    let e = read2("run,t,rail,hinge\na,0,1e308,0\na,0.01,-1e308,0\na,0.02,0,0\n").unwrap_err();
    assert!(
        matches!(&e, DataError::Overflow { line: 3, column, .. } if column == "rail"),
        "{e}"
    );
    let e = read2("run,t,rail,hinge\na,0,0,0\na,5e-324,0,0\na,1e-323,0,0\n").unwrap_err();
    assert!(
        matches!(&e, DataError::TimeStepOutOfRange { run, dt } if run == "a" && *dt == 5e-324),
        "{e}"
    );
    // resampled runs are checked too (the run's first line is named)
    let opts = ReadOptions {
        resample: Some(0.01),
        ..Default::default()
    };
    assert!(matches!(
        Dataset::<2>::read_for::<CartpoleMinimal, 0, _>(
            "run,t,rail,hinge\na,0,0,0\na,0.02,1e308,0\na,0.04,-1e308,0\n".as_bytes(),
            &opts
        ),
        Err(DataError::Overflow { line: 2, .. })
    ));
    // every accepted reading gives finite states
    let d = read2("run,t,rail,hinge\na,0,1e300,3\na,0.01,1e300,-3\na,0.02,1e300,3\n").unwrap();
    for k in 0..2 {
        let z = d.runs[0].state(k).unwrap();
        assert!(z.q.iter().chain(z.v.iter()).all(|x| x.is_finite()));
    }
}

/// One dropped sample is reported at the line that ends the gap, not at
/// the regular steps before it (the reference is the median step).
#[test]
fn a_dropped_sample_is_reported_at_its_own_line() {
    let text = "run,t,pivot\na,0,0\na,0.01,0.01\na,0.03,0.03\na,0.04,0.04\na,0.05,0.05\n";
    match read1(text, &ReadOptions::default()) {
        Err(DataError::NonUniformTime {
            line,
            expected,
            found,
            ..
        }) => {
            assert_eq!(line, 4);
            assert!((expected - 0.01).abs() < 1e-15 && (found - 0.02).abs() < 1e-15);
        }
        other => panic!("{other:?}"),
    }
}

/// An evenly sampled 120 Hz log whose timestamps were printed with few
/// decimals passes (its steps differ by a printed unit, up to 12 %), with
/// Δt the mean step; the same log with one sample dropped is still refused
/// at the gap. Timestamps printed in exponent form count their digits too.
#[test]
fn rounded_timestamps_of_an_even_log_pass_and_a_gap_does_not() {
    let h = 1.0 / 120.0;
    let log = |decimals: usize, skip: Option<usize>, exponent: bool| {
        let mut text = String::from("run,t,pivot\n");
        for k in (0..241).filter(|k| Some(*k) != skip) {
            let t = k as f64 * h;
            let t = if exponent {
                format!("{t:.decimals$e}")
            } else {
                format!("{t:.decimals$}")
            };
            text += &format!("a,{t},{}\n", 0.1 * (k as f64 * h).sin());
        }
        text
    };
    for (decimals, exponent) in [(3, false), (4, false), (5, false), (3, true)] {
        let d = read1(&log(decimals, None, exponent), &ReadOptions::default())
            .unwrap_or_else(|e| panic!("{decimals} decimals (exponent {exponent}): {e}"));
        let dt = d.runs[0].dt.unwrap();
        // the mean step of 240 steps: off by at most two half-units / 240
        assert!(
            (dt - h).abs() <= 1e-5 / 240.0,
            "{decimals} decimals: dt {dt}"
        );
        match read1(&log(decimals, Some(100), exponent), &ReadOptions::default()) {
            // rows k = 0..99 are lines 2..101; k = 101 ends the gap
            Err(DataError::NonUniformTime { line, .. }) => assert_eq!(line, 102),
            other => panic!("{decimals} decimals, a dropped sample: {other:?}"),
        }
    }
    // without the rounding allowance the 3-decimal log fails: the steps
    // (0.008 or 0.009) differ from the median by 12 %
    let text = log(3, None, false);
    let steps: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse::<f64>().unwrap())
        .collect::<Vec<_>>()
        .windows(2)
        .map(|w| w[1] - w[0])
        .collect();
    assert!(steps.iter().any(|s| (s - 0.008).abs() < 1e-12));
    assert!(steps.iter().any(|s| (s - 0.009).abs() < 1e-12));
}

/// `Dataset::dt` and `check_dt` refuse NaN arguments, with which every
/// comparison would pass.
#[test]
fn time_step_checks_refuse_nan() {
    let d = read1(
        "run,t,pivot\na,0,0\na,0.01,0.01\nb,0,0\nb,0.05,0.01\n",
        &ReadOptions::default(),
    )
    .unwrap();
    assert!(matches!(
        d.dt(1e-6),
        Err(DataError::TimeStepMismatch { .. })
    ));
    assert!(matches!(
        d.dt(f64::NAN),
        Err(DataError::InvalidOption { .. })
    ));
    assert!(matches!(
        d.check_dt(f64::NAN, 1e-6),
        Err(DataError::InvalidOption { .. })
    ));
    assert!(matches!(
        d.check_dt(0.01, f64::NAN),
        Err(DataError::InvalidOption { .. })
    ));
    assert!(matches!(
        d.check_dt(1e300, 1e-6),
        Err(DataError::InvalidOption { .. })
    ));
    assert!(matches!(
        d.check_dt(0.01, 1e-6),
        Err(DataError::TimeStepMismatch { .. })
    ));
}

#[test]
fn empty_runs_files_and_labels() {
    let e = read2("").unwrap_err();
    assert!(matches!(e, DataError::Empty(_)), "{e}");
    let e = read2("run,t,rail,hinge\n").unwrap_err();
    assert!(matches!(e, DataError::Empty(_)), "{e}");
    // an empty run label
    let e = read2("run,t,rail,hinge\n,0,0,0\n").unwrap_err();
    assert!(matches!(e, DataError::EmptyRun { line: 2 }), "{e}");
    // a run that reappears after another
    let e = read2("run,t,rail,hinge\na,0,0,0\nb,0,0,0\na,0.01,0,0\n").unwrap_err();
    assert!(
        matches!(&e, DataError::RunNotContiguous { run, line: 4 } if run == "a"),
        "{e}"
    );
}

/// One-row and two-row runs are kept but give no transitions, as
/// documented; a file of only one-row runs has no time step.
#[test]
fn one_row_runs_are_kept_without_transitions() {
    let d =
        read2("run,t,rail,hinge\na,0,0,0\nb,0,0,0\nb,0.01,0,0\nc,0,0,0\nc,0.01,1,0\nc,0.02,3,0\n")
            .unwrap();
    assert_eq!(d.runs.len(), 3);
    assert_eq!(d.runs[0].dt, None);
    assert!(d.runs[0].state(0).is_none());
    assert_eq!(
        d.short_runs().map(|r| r.name.as_str()).collect::<Vec<_>>(),
        ["a", "b"]
    );
    assert_eq!(d.transitions().len(), 1);
    assert_eq!(d.samples(), 6);
    let d = read2("run,t,rail,hinge\na,0,0,0\nb,0,0,0\n").unwrap();
    assert!(d.transitions().is_empty());
    assert!(matches!(d.dt(1e-6), Err(DataError::NoTimeStep)));
}

#[test]
fn reading_by_names_and_kinds_and_from_files() {
    let names = ["x", "theta"];
    let kinds = [CoordinateKind::Length, CoordinateKind::Angle];
    let d = Dataset::read_csv(
        "run,t,x,theta\n1,0,0,3.1\n1,0.1,0,-3.1\n".as_bytes(),
        &names,
        &kinds,
        &ReadOptions::default(),
    )
    .unwrap();
    assert!((d.runs[0].positions[1][1] - (2.0 * PI - 3.1)).abs() < 1e-12);
    let e = Dataset::read_path("/nonexistent.csv", &names, &kinds, &ReadOptions::default())
        .unwrap_err();
    assert!(matches!(e, DataError::Io { .. }), "{e}");
    let e = Dataset::read_csv(
        "run,t,x,theta\n".as_bytes(),
        &names,
        &kinds,
        &ReadOptions {
            time_tolerance: f64::NAN,
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, DataError::InvalidOption { .. }), "{e}");
}

vigp::mechanism! {
    /// A cartpole pushed along its rail and driven at the hinge.
    pub DrivenCartpole {
        links {
            cart: { mass: 1.0, length: 1.0 },
            pole: { mass: 1.0, length: 1.0 },
        }
        joints {
            rail: prismatic(world, cart.center) { axis: [1.0, 0.0], actuated },
            hinge: revolute(cart.center, pole.start) { actuated },
        }
    }
}

/// `u_<joint>` columns of an actuated mechanism: required, in any order,
/// checked like coordinates, zero-order held when resampling; the step
/// from state k is driven by row k+1's input.
#[test]
fn input_columns_are_read() {
    let read = |text: &str, opts: &ReadOptions| {
        Dataset::<2>::read_for::<DrivenCartpoleMinimal, 0, _>(text.as_bytes(), opts)
    };
    let read_err = |text: &str| read(text, &ReadOptions::default()).unwrap_err();
    let text = "run,t,u_hinge,rail,hinge,u_rail\n\
                a,0.0,0.5,0.0,0.1,1.0\n\
                a,0.1,0.6,0.1,0.2,2.0\n\
                a,0.2,0.7,0.3,0.3,3.0\n";
    let d = read(text, &ReadOptions::default()).unwrap();
    assert_eq!(d.inputs, vec!["rail", "hinge"]);
    let r = &d.runs[0];
    assert_eq!(
        r.inputs,
        vec![vec![1.0, 0.5], vec![2.0, 0.6], vec![3.0, 0.7]]
    );
    assert_eq!(r.step_input(0), Some(&[2.0, 0.6][..]));
    assert_eq!(r.step_input(2), None);
    // a missing input column, a bad value
    let e = read_err("run,t,rail,hinge,u_rail\na,0,0,0,1\n");
    assert!(
        matches!(&e, DataError::MissingColumn { name, .. } if name == "u_hinge"),
        "{e}"
    );
    let e = read_err("run,t,rail,hinge,u_rail,u_hinge\na,0,0,0,1,nan\n");
    assert!(
        matches!(&e, DataError::NonFinite { column, .. } if column == "u_hinge"),
        "{e}"
    );
    let e = read_err("run,t,rail,hinge,u_rail,u_hinge,u_elbow\na,0,0,0,1,1,1\n");
    assert!(e.to_string().contains("u_<actuated joint>"), "{e}");
    // resampling holds the input (zero-order hold), positions interpolate
    let opts = ReadOptions {
        resample: Some(0.05),
        ..ReadOptions::default()
    };
    let d = read(text, &opts).unwrap();
    let r = &d.runs[0];
    assert_eq!(r.positions.len(), 5);
    assert_eq!(r.inputs.len(), 5);
    assert_eq!(r.inputs[1], vec![1.0, 0.5]);
    assert_eq!(r.inputs[2], vec![2.0, 0.6]);
    assert_eq!(r.inputs[3], vec![2.0, 0.6]);
    assert_eq!(r.inputs[4], vec![3.0, 0.7]);
    assert!((r.positions[1][0] - 0.05).abs() < 1e-12);
}

/// Resampling at the logging rate changes nothing: times logged with two
/// decimals from t = 0.50 (so t0 + k·Δt rounds a hair below some logged
/// times, 0.50 + 18·0.01 = 0.6799999999999999 < 0.68), input = row
/// index; every resampled sample holds its own row's input. Before the
/// fix 11 of 200 rows held the previous row's.
#[test]
fn resampling_at_the_logging_rate_holds_each_rows_own_input() {
    let mut text = String::from("run,t,rail,hinge,u_rail,u_hinge\n");
    for i in 0..200 {
        let t = 0.5 + 0.01 * i as f64;
        text += &format!(
            "a,{t:.2},{},{},{i},{}\n",
            0.001 * i as f64,
            0.1,
            -(i as f64)
        );
    }
    let opts = ReadOptions {
        resample: Some(0.01),
        ..ReadOptions::default()
    };
    let d = Dataset::<2>::read_for::<DrivenCartpoleMinimal, 0, _>(text.as_bytes(), &opts).unwrap();
    let r = &d.runs[0];
    assert_eq!(r.inputs.len(), 200);
    let wrong: Vec<usize> = (0..200)
        .filter(|&i| r.inputs[i] != vec![i as f64, -(i as f64)])
        .collect();
    assert!(
        wrong.is_empty(),
        "rows holding another row's input: {wrong:?}"
    );
    for (i, p) in r.positions.iter().enumerate() {
        assert!((p[0] - 0.001 * i as f64).abs() <= 1e-15, "row {i}");
    }
}

/// `Dataset::forced_transitions` pairs each transition with the input of
/// its step (row k+1's, as `Run::step_input`) and the previous input (row
/// k's, which produced the state's velocity), equal to
/// `learned::forced_transitions` on the run's arrays; asked for another
/// input count it is a typed error.
#[test]
fn forced_transitions_take_each_steps_input() {
    let text = "run,t,rail,hinge,u_rail,u_hinge\n\
                a,0.0,0.0,0.1,1.0,0.5\n\
                a,0.1,0.1,0.2,2.0,0.6\n\
                a,0.2,0.3,0.3,3.0,0.7\n\
                a,0.3,0.6,0.5,4.0,0.8\n\
                b,0.0,1.0,1.0,9.0,9.0\n";
    let d = Dataset::<2>::read_for::<DrivenCartpoleMinimal, 0, _>(
        text.as_bytes(),
        &ReadOptions::default(),
    )
    .unwrap();
    let f = d.forced_transitions::<2>().unwrap();
    // run a: 4 rows → 2 transitions; run b (one row) none
    assert_eq!(f.len(), 2);
    let r = &d.runs[0];
    for (k, t) in f.iter().enumerate() {
        assert_eq!(t.z, r.state(k).unwrap());
        assert_eq!(t.u.as_slice(), r.step_input(k).unwrap());
        assert_eq!(t.u_prev.as_slice(), r.inputs[k].as_slice());
        assert_eq!(t.v_next, r.state(k + 1).unwrap().v);
    }
    assert_eq!(f[0].u.as_slice(), &[2.0, 0.6]);
    assert_eq!(f[0].u_prev.as_slice(), &[1.0, 0.5]);
    let us: Vec<SVector<f64, 2>> = r
        .inputs
        .iter()
        .map(|u| SVector::from_column_slice(u))
        .collect();
    assert_eq!(
        f,
        vigp::learned::forced_transitions(&r.positions, &us, r.dt.unwrap())
    );
    let e = d.forced_transitions::<1>().unwrap_err();
    assert!(
        matches!(
            e,
            DataError::InputCount {
                expected: 1,
                found: 2
            }
        ),
        "{e}"
    );
}
