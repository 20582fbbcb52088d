//! Sweeps split across processes or machines, shared by `#[path]` between
//! the examples that sweep (`paper`, `scale_sweep`) and their tests.
//!
//! A sweep is a list of independent units of work (for the paper: Fig. 1,
//! one run of one system, the error bounds of one system), each computed
//! from its own seed, so that its result does not depend on which process
//! computes it or in which order. `--shard i/N` (0-based: `0/4` … `3/4`)
//! computes the units whose position `k` in the sweep's list has
//! `k mod N = i` and writes their raw results, every float exact, to
//! `shard.json` in its own folder. `merge` reads the N folders, checks
//! that they belong to one sweep and hold every unit exactly once, and
//! hands the units back in the sweep's order; the example then writes the
//! same report as a run without `--shard`, which goes through the same
//! code.
//!
//! Floats in `shard.json`: finite values as JSON numbers (shortest
//! round-trip digits; read back exactly, serde_json's `float_roundtrip`),
//! NaN and ±∞ as the strings `"NaN"`, `"inf"`, `"-inf"`.

#![allow(dead_code)] // each example uses its own part of this file

use serde::de::DeserializeOwned;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::collections::BTreeMap;
use std::fmt::Debug;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// The file each shard writes into its folder.
pub const FILE: &str = "shard.json";

/// What can go wrong when sharding or merging.
#[derive(Debug, thiserror::Error)]
pub enum ShardError {
    /// `--shard` is not `i/N` with 0 ≤ i < N.
    #[error("--shard `{0}`: expected i/N with 0 <= i < N (0-based, e.g. 0/4 … 3/4)")]
    Spec(String),
    /// Reading or writing a shard file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A shard file is not valid JSON of the expected shape.
    #[error("{}: not a shard file of this example: {source}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: serde_json::Error,
    },
    /// `merge` was given no folder.
    #[error("merge needs at least one shard folder")]
    NoShards,
    /// A shard file written by another example or format version.
    #[error("{}: format `{found}`, expected `{expected}`", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// Its format tag.
        found: String,
        /// The tag this example writes.
        expected: String,
    },
    /// Shards of sweeps split into different numbers of shards.
    #[error(
        "{}: shard {index}/{count}, but {} is one of {first_count}",
        path.display(),
        first.display()
    )]
    Count {
        /// The file.
        path: PathBuf,
        /// Its shard index.
        index: usize,
        /// Its shard count.
        count: usize,
        /// The first file.
        first: PathBuf,
        /// The first file's shard count.
        first_count: usize,
    },
    /// The same shard given twice.
    #[error("shard {index}/{count} given twice: {} and {}", a.display(), b.display())]
    DuplicateShard {
        /// The shard index.
        index: usize,
        /// The shard count.
        count: usize,
        /// One file.
        a: PathBuf,
        /// The other.
        b: PathBuf,
    },
    /// A shard missing from the merge.
    #[error("shard {index}/{count} is missing")]
    MissingShard {
        /// The shard index.
        index: usize,
        /// The shard count.
        count: usize,
    },
    /// Shards run with different options (seed, systems, N, …).
    #[error(
        "{}: options differ from {}'s:\n  {found}\nvs\n  {expected}",
        path.display(),
        first.display()
    )]
    Options {
        /// The file.
        path: PathBuf,
        /// The first file.
        first: PathBuf,
        /// This file's options.
        found: String,
        /// The first file's options.
        expected: String,
    },
    /// A unit that the options do not call for.
    #[error("{}: unit {unit} is not part of this sweep", path.display())]
    UnexpectedUnit {
        /// The file.
        path: PathBuf,
        /// The unit.
        unit: String,
    },
    /// A unit in a shard that does not own it.
    #[error(
        "{}: unit {unit} belongs to shard {owner}/{count}, not {index}/{count}",
        path.display()
    )]
    WrongShard {
        /// The file.
        path: PathBuf,
        /// The unit.
        unit: String,
        /// The shard that owns it.
        owner: usize,
        /// The file's shard index.
        index: usize,
        /// The shard count.
        count: usize,
    },
    /// A unit present twice.
    #[error("unit {unit} is present twice ({} and {})", a.display(), b.display())]
    DuplicateUnit {
        /// The unit.
        unit: String,
        /// One file.
        a: PathBuf,
        /// The other.
        b: PathBuf,
    },
    /// A unit absent from every shard.
    #[error("unit {unit} is missing (shard {owner}/{count} should hold it)")]
    MissingUnit {
        /// The unit.
        unit: String,
        /// The shard that should hold it.
        owner: usize,
        /// The shard count.
        count: usize,
    },
}

/// One part of a sweep: shard `index` of `count`, 0-based.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// 0 ≤ index < count.
    pub index: usize,
    /// Number of shards, ≥ 1.
    pub count: usize,
}

impl Shard {
    /// The whole sweep in one shard.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Whether the unit at position `unit` in the sweep's list is this shard's.
    pub fn owns(&self, unit: usize) -> bool {
        unit % self.count == self.index
    }

    /// The folder name of this shard, `shard-i-of-N`.
    pub fn dir_name(&self) -> String {
        format!("shard-{}-of-{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = ShardError;
    fn from_str(s: &str) -> Result<Self, ShardError> {
        let bad = || ShardError::Spec(s.to_string());
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count): (usize, usize) = (
            i.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// What one shard writes: the format tag of the example, the shard, the
/// options of the sweep and the results of its units.
#[derive(Debug, Serialize, Deserialize)]
pub struct ShardFile<O, U> {
    /// The example's tag, e.g. `vigp-paper-shard/1`.
    pub format: String,
    /// Which shard.
    pub shard: Shard,
    /// The options every shard of the sweep must share.
    pub options: O,
    /// The units computed, each with its key.
    pub units: Vec<U>,
}

/// The result of one unit of work, which names its unit.
pub trait UnitResult {
    /// The unit's name (its key in the sweep's list).
    type Key: Ord + Clone + Debug;
    /// The unit this result belongs to.
    fn key(&self) -> Self::Key;
}

/// Writes `dir/shard.json` and returns its path.
pub fn write<O: Serialize, U: Serialize>(
    dir: &Path,
    format: &str,
    shard: Shard,
    options: &O,
    units: &[U],
) -> Result<PathBuf, ShardError> {
    let path = dir.join(FILE);
    let io = |source| ShardError::Io {
        path: path.clone(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(io)?;
    /// [`ShardFile`], borrowed.
    #[derive(Serialize)]
    struct Borrowed<'a, O, U> {
        format: &'a str,
        shard: Shard,
        options: &'a O,
        units: &'a [U],
    }
    let file = Borrowed {
        format,
        shard,
        options,
        units,
    };
    let text = serde_json::to_string_pretty(&file).map_err(|source| ShardError::Json {
        path: path.clone(),
        source,
    })?;
    std::fs::write(&path, text + "\n").map_err(io)?;
    Ok(path)
}

/// Reads a shard file: `path` is the shard's folder or the file itself.
pub fn read<O: DeserializeOwned, U: DeserializeOwned>(
    path: &Path,
) -> Result<(PathBuf, ShardFile<O, U>), ShardError> {
    let path = if path.is_dir() {
        path.join(FILE)
    } else {
        path.to_path_buf()
    };
    let text = std::fs::read_to_string(&path).map_err(|source| ShardError::Io {
        path: path.clone(),
        source,
    })?;
    let file = serde_json::from_str(&text).map_err(|source| ShardError::Json {
        path: path.clone(),
        source,
    })?;
    Ok((path, file))
}

/// Checks that `files` are the shards of one sweep, each present once, with
/// the same `format` tag and options, and every unit of `expected(options)`
/// (the sweep's list, in order) present exactly once in the shard that owns
/// it. Returns the options and the units in the sweep's order.
pub fn merge<O, U>(
    files: Vec<(PathBuf, ShardFile<O, U>)>,
    format: &str,
    expected: impl Fn(&O) -> Vec<U::Key>,
) -> Result<(O, Vec<U>), ShardError>
where
    O: PartialEq + Debug,
    U: UnitResult,
{
    let mut files = files.into_iter();
    let (first_path, first) = files.next().ok_or(ShardError::NoShards)?;
    let count = first.shard.count;
    let options = first.options;
    let mut seen: Vec<Option<PathBuf>> = vec![None; count];
    let mut units: Vec<(PathBuf, Shard, Vec<U>)> = Vec::new();
    let rest = files.map(|(p, f)| (p, f.format, f.shard, Some(f.options), f.units));
    let head = std::iter::once((
        first_path.clone(),
        first.format,
        first.shard,
        None,
        first.units,
    ));
    for (path, tag, shard, opts, list) in head.chain(rest) {
        if tag != format {
            return Err(ShardError::Format {
                path,
                found: tag,
                expected: format.to_string(),
            });
        }
        if shard.count != count || shard.index >= count {
            return Err(ShardError::Count {
                path,
                index: shard.index,
                count: shard.count,
                first: first_path,
                first_count: count,
            });
        }
        if let Some(o) = opts.filter(|o| *o != options) {
            return Err(ShardError::Options {
                path,
                first: first_path,
                found: format!("{o:?}"),
                expected: format!("{options:?}"),
            });
        }
        if let Some(a) = &seen[shard.index] {
            return Err(ShardError::DuplicateShard {
                index: shard.index,
                count,
                a: a.clone(),
                b: path,
            });
        }
        seen[shard.index] = Some(path.clone());
        units.push((path, shard, list));
    }
    if let Some(index) = seen.iter().position(Option::is_none) {
        return Err(ShardError::MissingShard { index, count });
    }
    let keys = expected(&options);
    let position: BTreeMap<U::Key, usize> = keys
        .iter()
        .enumerate()
        .map(|(k, u)| (u.clone(), k))
        .collect();
    let mut slots: Vec<Option<(PathBuf, U)>> = (0..keys.len()).map(|_| None).collect();
    for (path, shard, list) in units {
        for u in list {
            let key = u.key();
            let Some(&k) = position.get(&key) else {
                return Err(ShardError::UnexpectedUnit {
                    path,
                    unit: format!("{key:?}"),
                });
            };
            if !shard.owns(k) {
                return Err(ShardError::WrongShard {
                    path,
                    unit: format!("{key:?}"),
                    owner: k % count,
                    index: shard.index,
                    count,
                });
            }
            if let Some((a, _)) = &slots[k] {
                return Err(ShardError::DuplicateUnit {
                    unit: format!("{key:?}"),
                    a: a.clone(),
                    b: path,
                });
            }
            slots[k] = Some((path.clone(), u));
        }
    }
    let mut out = Vec::with_capacity(keys.len());
    for (k, slot) in slots.into_iter().enumerate() {
        match slot {
            Some((_, u)) => out.push(u),
            None => {
                return Err(ShardError::MissingUnit {
                    unit: format!("{:?}", keys[k]),
                    owner: k % count,
                    count,
                });
            }
        }
    }
    Ok((options, out))
}

/// `#[serde(with = "shard::exact")]`: floats (alone, in vectors, options
/// and pairs) written so that they read back bit for bit, NaN and ±∞
/// included (as `"NaN"`, `"inf"`, `"-inf"`). Finite values go through
/// `serialize_f64`, so CSV and JSON writers print them as before.
pub mod exact {
    use super::*;

    /// A float that round-trips through JSON, NaN and ±∞ included.
    #[derive(Clone, Copy, Debug)]
    pub struct F64(pub f64);

    impl Serialize for F64 {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            if self.0.is_finite() {
                s.serialize_f64(self.0)
            } else {
                // "NaN", "inf", "-inf": what `str::parse::<f64>` reads back
                s.serialize_str(&format!("{:?}", self.0))
            }
        }
    }

    impl<'de> Deserialize<'de> for F64 {
        fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            #[derive(Deserialize)]
            #[serde(untagged)]
            enum Repr {
                Number(f64),
                Text(String),
            }
            match Repr::deserialize(d)? {
                Repr::Number(v) => Ok(F64(v)),
                Repr::Text(t) => match t.parse::<f64>() {
                    Ok(v) if !v.is_finite() => Ok(F64(v)),
                    _ => Err(serde::de::Error::custom(format!(
                        "`{t}` is not NaN, inf or -inf"
                    ))),
                },
            }
        }
    }

    /// A type whose floats are written through [`F64`].
    pub trait Exact: Sized {
        /// The serialisable form.
        type Repr: Serialize + DeserializeOwned;
        /// To the serialisable form.
        fn to_repr(&self) -> Self::Repr;
        /// Back from it.
        fn from_repr(r: Self::Repr) -> Self;
    }

    impl Exact for f64 {
        type Repr = F64;
        fn to_repr(&self) -> F64 {
            F64(*self)
        }
        fn from_repr(r: F64) -> f64 {
            r.0
        }
    }

    impl Exact for String {
        type Repr = String;
        fn to_repr(&self) -> String {
            self.clone()
        }
        fn from_repr(r: String) -> String {
            r
        }
    }

    impl<T: Exact> Exact for Vec<T> {
        type Repr = Vec<T::Repr>;
        fn to_repr(&self) -> Self::Repr {
            self.iter().map(Exact::to_repr).collect()
        }
        fn from_repr(r: Self::Repr) -> Self {
            r.into_iter().map(T::from_repr).collect()
        }
    }

    impl<T: Exact> Exact for Option<T> {
        type Repr = Option<T::Repr>;
        fn to_repr(&self) -> Self::Repr {
            self.as_ref().map(Exact::to_repr)
        }
        fn from_repr(r: Self::Repr) -> Self {
            r.map(T::from_repr)
        }
    }

    impl<A: Exact, B: Exact> Exact for (A, B) {
        type Repr = (A::Repr, B::Repr);
        fn to_repr(&self) -> Self::Repr {
            (self.0.to_repr(), self.1.to_repr())
        }
        fn from_repr(r: Self::Repr) -> Self {
            (A::from_repr(r.0), B::from_repr(r.1))
        }
    }

    /// Serialises a field through its [`Exact`] form.
    pub fn serialize<T: Exact, S: Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
        v.to_repr().serialize(s)
    }

    /// Deserialises a field from its [`Exact`] form.
    pub fn deserialize<'de, T: Exact, D: Deserializer<'de>>(d: D) -> Result<T, D::Error> {
        T::Repr::deserialize(d).map(T::from_repr)
    }
}
