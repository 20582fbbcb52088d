//! The sharding of the sweeps (`examples/common/shard.rs`): the partition,
//! the exact float round trip of the shard files, and `merge` on a small
//! sweep, against the same sweep unsharded and with every kind of broken
//! set of shards. The examples themselves are checked end to end by
//! `scripts/shard_check.sh` (release builds: a tiny `paper` and
//! `scale_sweep` sweep unsharded and in shards, merged, `diff -r`).

#[path = "../common/shard.rs"]
mod shard;

use serde::{Deserialize, Serialize};
use shard::exact::F64;
use shard::{Shard, ShardError, UnitResult};
use std::path::{Path, PathBuf};

const FORMAT: &str = "test-sweep/1";

/// The options of the toy sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Options {
    seed: u64,
    systems: Vec<String>,
    runs: usize,
    #[serde(with = "shard::exact")]
    scale: f64,
}

#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
enum Key {
    Summary,
    Run(String, usize),
}

/// A unit's result: floats that exercise the round trip (NaN, ±∞, −0,
/// subnormals and full-precision values drawn from the unit's own seed).
#[derive(Debug, Clone, Serialize, Deserialize)]
enum Out {
    Summary {
        #[serde(with = "shard::exact")]
        values: Vec<f64>,
    },
    Run {
        system: String,
        run: usize,
        #[serde(with = "shard::exact")]
        values: Vec<f64>,
        #[serde(with = "shard::exact")]
        pair: Option<(f64, f64)>,
    },
}

impl UnitResult for Out {
    type Key = Key;
    fn key(&self) -> Key {
        match self {
            Out::Summary { .. } => Key::Summary,
            Out::Run { system, run, .. } => Key::Run(system.clone(), *run),
        }
    }
}

fn keys(o: &Options) -> Vec<Key> {
    let mut k = vec![Key::Summary];
    for s in &o.systems {
        k.extend((0..o.runs).map(|r| Key::Run(s.clone(), r)));
    }
    k
}

fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Computes one unit from (seed, system, run) alone.
fn compute(o: &Options, key: &Key) -> Out {
    match key {
        Key::Summary => Out::Summary {
            values: vec![
                f64::NAN,
                f64::INFINITY,
                f64::NEG_INFINITY,
                -0.0,
                5e-324,
                o.scale,
            ],
        },
        Key::Run(system, run) => {
            let mut state = o.seed ^ (*run as u64 + 1).wrapping_mul(0x2545_F491_4F6C_DD1D);
            for b in system.bytes() {
                state = state.rotate_left(8) ^ u64::from(b);
            }
            // random bit patterns of finite floats, every exponent
            let values = (0..20)
                .map(|_| {
                    loop {
                        let v = f64::from_bits(splitmix(&mut state));
                        if v.is_finite() {
                            break v * o.scale;
                        }
                    }
                })
                .collect();
            let pair = (*run == 0).then(|| (0.1 + 0.2, f64::MIN_POSITIVE / 3.0));
            Out::Run {
                system: system.clone(),
                run: *run,
                values,
                pair,
            }
        }
    }
}

/// The toy sweep's shard `shard`, computed and written to `dir`.
fn run_shard(o: &Options, shard: Shard, dir: &Path) -> PathBuf {
    let units: Vec<Out> = keys(o)
        .iter()
        .enumerate()
        .filter(|(k, _)| shard.owns(*k))
        .map(|(_, key)| compute(o, key))
        .collect();
    shard::write(dir, FORMAT, shard, o, &units).expect("write shard")
}

/// Runs all `count` shards of the sweep, each into its own folder below
/// `root`; returns the folders in shard order.
fn run_shards(o: &Options, count: usize, root: &Path) -> Vec<PathBuf> {
    (0..count)
        .map(|index| {
            let dir = root.join(Shard { index, count }.dir_name());
            run_shard(o, Shard { index, count }, &dir);
            dir
        })
        .collect()
}

fn merge_dirs(dirs: &[PathBuf]) -> Result<(Options, Vec<Out>), ShardError> {
    let files = dirs
        .iter()
        .map(|d| shard::read::<Options, Out>(d))
        .collect::<Result<Vec<_>, _>>()?;
    shard::merge(files, FORMAT, keys)
}

/// Bit patterns of every float of a result list (NaN compared by bits too).
fn bits(units: &[Out]) -> Vec<(Key, Vec<u64>)> {
    units
        .iter()
        .map(|u| {
            let b = match u {
                Out::Summary { values } => values.iter().map(|v| v.to_bits()).collect(),
                Out::Run { values, pair, .. } => values
                    .iter()
                    .chain(pair.iter().flat_map(|(a, b)| [a, b]))
                    .map(|v| v.to_bits())
                    .collect(),
            };
            (u.key(), b)
        })
        .collect()
}

/// A fresh directory under the system's temporary directory.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vigp-sharding-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn options() -> Options {
    Options {
        seed: 7,
        systems: vec!["pendulum".into(), "cartpole".into(), "fourbar".into()],
        runs: 5,
        scale: 1.0 / 3.0,
    }
}

#[test]
fn shard_spec_is_zero_based_i_of_n() {
    assert_eq!(
        "0/4".parse::<Shard>().unwrap(),
        Shard { index: 0, count: 4 }
    );
    assert_eq!(
        "3/4".parse::<Shard>().unwrap(),
        Shard { index: 3, count: 4 }
    );
    for bad in ["4/4", "1/0", "0/0", "-1/4", "a/4", "1/b", "3", "", "1/2/3"] {
        assert!(
            matches!(bad.parse::<Shard>(), Err(ShardError::Spec(_))),
            "{bad} accepted"
        );
    }
}

#[test]
fn every_unit_in_exactly_one_shard() {
    for count in 1..=7 {
        for unit in 0..50 {
            let owners = (0..count)
                .filter(|&index| Shard { index, count }.owns(unit))
                .count();
            assert_eq!(owners, 1, "unit {unit} of {count} shards");
        }
    }
}

#[test]
fn floats_round_trip_bit_for_bit() {
    let mut state = 1u64;
    let mut values = vec![
        0.0,
        -0.0,
        5e-324,
        -5e-324,
        f64::MIN_POSITIVE,
        f64::MAX,
        f64::MIN,
        f64::EPSILON,
        0.1 + 0.2,
        1e16,
        123456.0,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    values.extend(
        (0..2000)
            .map(|_| f64::from_bits(splitmix(&mut state)))
            .filter(|v| !v.is_nan()),
    );
    for v in values {
        let json = serde_json::to_string(&F64(v)).unwrap();
        let back: F64 = serde_json::from_str(&json).unwrap();
        assert_eq!(back.0.to_bits(), v.to_bits(), "{v:?} → {json}");
    }
    let nan: F64 = serde_json::from_str(&serde_json::to_string(&F64(f64::NAN)).unwrap()).unwrap();
    assert!(nan.0.is_nan());
    assert!(
        serde_json::from_str::<F64>("\"1.5\"").is_err(),
        "finite numbers are numbers"
    );
    assert!(serde_json::from_str::<F64>("\"x\"").is_err());
}

/// The CSV files of the paper example serialise fields through `F64`: the
/// text must be what the `csv` crate writes for a plain `f64`.
#[test]
fn csv_text_is_unchanged() {
    #[derive(Serialize)]
    struct Plain {
        v: f64,
    }
    #[derive(Serialize)]
    struct Wrapped {
        #[serde(with = "shard::exact")]
        v: f64,
    }
    let mut state = 3u64;
    let mut values = vec![
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        -0.0,
        1e300,
        1.5e-7,
    ];
    values.extend((0..500).map(|_| f64::from_bits(splitmix(&mut state))));
    for v in values {
        let text = |f: &dyn Fn(&mut csv::Writer<Vec<u8>>)| {
            let mut w = csv::Writer::from_writer(Vec::new());
            f(&mut w);
            String::from_utf8(w.into_inner().unwrap()).unwrap()
        };
        let plain = text(&|w| w.serialize(Plain { v }).unwrap());
        let wrapped = text(&|w| w.serialize(Wrapped { v }).unwrap());
        assert_eq!(plain, wrapped, "{v:?}");
    }
}

#[test]
fn merged_shards_equal_the_unsharded_sweep() {
    let o = options();
    let whole: Vec<Out> = keys(&o).iter().map(|k| compute(&o, k)).collect();
    let root = scratch("merge");
    // one shard: the unsharded sweep, through the file
    let one = run_shard(&o, Shard::WHOLE, &root.join("whole"));
    let (_, merged_one) = merge_dirs(&[one]).unwrap();
    assert_eq!(bits(&merged_one), bits(&whole));
    for count in [2, 4, 16, 17, 20] {
        let dirs = run_shards(&o, count, &root);
        // any order of the folders
        let mut shuffled = dirs.clone();
        shuffled.reverse();
        shuffled.rotate_left(count / 3);
        let (opts, merged) = merge_dirs(&shuffled).unwrap();
        assert_eq!(opts, o);
        assert_eq!(bits(&merged), bits(&whole), "{count} shards");
    }
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn broken_shard_sets_are_typed_errors() {
    let o = options();
    let root = scratch("broken");
    let count = 4;
    let dirs = run_shards(&o, count, &root);
    assert!(merge_dirs(&dirs).is_ok());

    assert!(matches!(merge_dirs(&[]), Err(ShardError::NoShards)));
    assert!(matches!(
        merge_dirs(&dirs[..3]),
        Err(ShardError::MissingShard { index: 3, count: 4 })
    ));
    let twice = [dirs.clone(), vec![dirs[1].clone()]].concat();
    assert!(matches!(
        merge_dirs(&twice),
        Err(ShardError::DuplicateShard { index: 1, .. })
    ));
    assert!(matches!(
        merge_dirs(&[root.join("absent")]),
        Err(ShardError::Io { .. })
    ));

    // a shard of another seed
    let other = Options {
        seed: 8,
        ..o.clone()
    };
    let odd = root.join("other-seed");
    run_shard(&other, Shard { index: 2, count }, &odd);
    let mixed = [
        dirs[0].clone(),
        dirs[1].clone(),
        odd.clone(),
        dirs[3].clone(),
    ];
    assert!(matches!(
        merge_dirs(&mixed),
        Err(ShardError::Options { .. })
    ));

    // a shard of a sweep split in 3
    let three = root.join("of-three");
    run_shard(&o, Shard { index: 2, count: 3 }, &three);
    let mixed = [dirs[0].clone(), dirs[1].clone(), three, dirs[3].clone()];
    assert!(matches!(merge_dirs(&mixed), Err(ShardError::Count { .. })));

    // hand-edited shard files: a unit dropped, duplicated, moved or foreign
    let edit = |name: &str, f: &dyn Fn(&mut Vec<Out>, &Options)| -> Vec<PathBuf> {
        let (_, mut file) = shard::read::<Options, Out>(&dirs[1]).unwrap();
        f(&mut file.units, &o);
        let dir = root.join(name);
        shard::write(&dir, FORMAT, file.shard, &file.options, &file.units).unwrap();
        vec![dirs[0].clone(), dir, dirs[2].clone(), dirs[3].clone()]
    };
    let dropped = edit("dropped", &|u, _| {
        u.pop();
    });
    assert!(matches!(
        merge_dirs(&dropped),
        Err(ShardError::MissingUnit { owner: 1, .. })
    ));
    let duplicated = edit("duplicated", &|u, _| u.push(u[0].clone()));
    assert!(matches!(
        merge_dirs(&duplicated),
        Err(ShardError::DuplicateUnit { .. })
    ));
    // unit 0 (the summary) belongs to shard 0
    let moved = edit("moved", &|u, o| u.push(compute(o, &Key::Summary)));
    assert!(matches!(
        merge_dirs(&moved),
        Err(ShardError::WrongShard {
            owner: 0,
            index: 1,
            ..
        })
    ));
    let foreign = edit("foreign", &|u, o| {
        u.push(compute(o, &Key::Run("cartpole".into(), 99)))
    });
    assert!(matches!(
        merge_dirs(&foreign),
        Err(ShardError::UnexpectedUnit { .. })
    ));

    // another example's shard file, and a file that is not one
    let (_, file) = shard::read::<Options, Out>(&dirs[2]).unwrap();
    let alien = root.join("alien");
    shard::write(
        &alien,
        "other-sweep/1",
        file.shard,
        &file.options,
        &file.units,
    )
    .unwrap();
    let mixed = [dirs[0].clone(), dirs[1].clone(), alien, dirs[3].clone()];
    assert!(matches!(merge_dirs(&mixed), Err(ShardError::Format { .. })));
    let junk = root.join("junk");
    std::fs::create_dir_all(&junk).unwrap();
    std::fs::write(junk.join(shard::FILE), "{\"format\": 1}").unwrap();
    assert!(matches!(merge_dirs(&[junk]), Err(ShardError::Json { .. })));
    let _ = std::fs::remove_dir_all(&root);
}
