//! Reading a dataset: one zarr group, or a folder of groups (`*.zarr` entries, read in name
//! order, as GPC's world-model data is stored), opened as one dataset whose episodes are the
//! groups' episodes in that order. Every group is checked alone (its arrays and episode ends)
//! and against the first (frame size, action and state widths), naming the group.

use std::fs;
use std::path::{Path, PathBuf};

use serde_json::Value;

use super::{Column, EpisodeArrays, ReplayError, ReplaySpec};
use crate::zarr::{ArrayReader, DType, ZarrError, read_attrs};

/// A dataset opened for reading; arrays are read lazily.
pub struct ReplayReader {
    /// The dataset: a group, or a folder of groups.
    pub path: PathBuf,
    /// `data/img` (bytes; float32 images in [0, 255] are rounded).
    pub img: Column,
    /// `data/action`.
    pub action: Column,
    /// `data/state`.
    pub state: Column,
    /// Exclusive cumulative episode ends, through all groups.
    pub episode_ends: Vec<usize>,
    /// The root `.zattrs` (of the first group, for a folder of groups).
    pub attrs: Value,
    /// The groups, in order, and the first episode of each.
    groups: Vec<(PathBuf, usize)>,
}

/// Opens array `dir` of a dataset whose root attributes are `attrs`. A dataset written
/// by evalharness (an `evalharness` attribute) never omits a chunk, so a missing one
/// is an error even where its older files declare fill value 0.
fn open_array(dir: &Path, attrs: &Value) -> Result<ArrayReader, ZarrError> {
    let a = ArrayReader::open(dir)?;
    Ok(if attrs.get("evalharness").is_some() { a.all_chunks_written() } else { a })
}

/// One group's arrays, checked alone.
struct Group {
    attrs: Value,
    img: ArrayReader,
    action: ArrayReader,
    state: ArrayReader,
    ends: Vec<usize>,
}

impl Group {
    fn open(path: &Path) -> Result<Self, ReplayError> {
        let layout = |reason: String| ReplayError::Layout { path: path.to_path_buf(), reason };
        let attrs = read_attrs(path)?;
        let open = |name: &str| {
            let p = path.join(name);
            if !p.join(".zarray").is_file() {
                return Err(layout(format!("missing array {name}")));
            }
            Ok(open_array(&p, &attrs)?)
        };
        let (img, action, state) = (open("data/img")?, open("data/action")?, open("data/state")?);
        let ends_arr = open("meta/episode_ends")?;
        let s = &img.meta.shape;
        if s.len() != 4 || s[3] != 3 || !matches!(img.dtype, DType::U8 | DType::F32) {
            return Err(layout(format!(
                "data/img must be N x H x W x 3 uint8 (or float32 in [0, 255]), got {:?} {}",
                s, img.meta.dtype
            )));
        }
        let n = img.rows();
        for (name, a) in [("data/action", &action), ("data/state", &state)] {
            if a.rows() != n || a.meta.shape.len() != 2 {
                return Err(layout(format!("{name} has shape {:?}, expected [{n}, d]", a.meta.shape)));
            }
        }
        let ends: Vec<usize> = ends_arr.read_f64()?.into_iter().map(|e| e as usize).collect();
        let monotone = ends.windows(2).all(|w| w[0] < w[1]) && ends.first().is_none_or(|&e| e > 0);
        if !monotone || ends.last().copied().unwrap_or(0) != n {
            return Err(layout(format!(
                "meta/episode_ends must increase strictly and end at {n} steps, ends at {:?}",
                ends.last()
            )));
        }
        Ok(Self { attrs, img, action, state, ends })
    }
}

/// The groups of `path`: itself if it is a group, else its `*.zarr` entries in name order.
pub(super) fn group_paths(path: &Path) -> Result<Vec<PathBuf>, ReplayError> {
    if path.join(".zgroup").is_file() {
        return Ok(vec![path.to_path_buf()]);
    }
    let layout = |reason: &str| ReplayError::Layout { path: path.to_path_buf(), reason: reason.into() };
    if !path.is_dir() {
        return Err(layout("no .zgroup (not a zarr v2 group)"));
    }
    let entries =
        fs::read_dir(path).map_err(|source| ReplayError::Io { path: path.to_path_buf(), source })?;
    let mut groups: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "zarr") && p.join(".zgroup").is_file())
        .collect();
    groups.sort();
    if groups.is_empty() {
        return Err(layout("no .zgroup (not a zarr v2 group) and no *.zarr groups in it"));
    }
    Ok(groups)
}

impl ReplayReader {
    /// Opens and validates a dataset: a zarr group, or a folder of them.
    ///
    /// # Errors
    /// [`ReplayError::Layout`] naming the group and the first missing or inconsistent part.
    pub fn open(path: &Path) -> Result<Self, ReplayError> {
        let paths = group_paths(path)?;
        let mut opened = Vec::with_capacity(paths.len());
        for p in &paths {
            let g = Group::open(p)?;
            if let Some(first) = opened.first() {
                let first: &Group = first;
                let row = |a: &ArrayReader| a.meta.shape[1..].to_vec();
                for (name, a, b) in [
                    ("data/img", &g.img, &first.img),
                    ("data/action", &g.action, &first.action),
                    ("data/state", &g.state, &first.state),
                ] {
                    if row(a) != row(b) {
                        return Err(ReplayError::Layout {
                            path: p.clone(),
                            reason: format!(
                                "{name} rows are {:?}, {}'s are {:?}: the groups of a folder must agree",
                                row(a),
                                paths[0].display(),
                                row(b)
                            ),
                        });
                    }
                }
            }
            opened.push(g);
        }
        let mut episode_ends = Vec::new();
        let (mut groups, mut offset) = (Vec::with_capacity(paths.len()), 0);
        for (p, g) in paths.iter().zip(&opened) {
            groups.push((p.clone(), episode_ends.len()));
            episode_ends.extend(g.ends.iter().map(|e| e + offset));
            offset += g.img.rows();
        }
        let column = |f: fn(&Group) -> &ArrayReader, name: &str, image: bool| {
            let parts = opened.iter().map(|g| f(g).clone()).collect();
            Column::new(parts, paths.iter().map(|p| p.join(name)).collect(), image)
        };
        let img = column(|g| &g.img, "data/img", true);
        let action = column(|g| &g.action, "data/action", false);
        let state = column(|g| &g.state, "data/state", false);
        let attrs = opened.swap_remove(0).attrs;
        Ok(Self { path: path.to_path_buf(), img, action, state, episode_ends, attrs, groups })
    }

    /// Number of episodes.
    pub fn episodes(&self) -> usize {
        self.episode_ends.len()
    }

    /// Total steps.
    pub fn steps(&self) -> usize {
        self.img.rows()
    }

    /// Step range `[start, end)` of episode `i`.
    pub fn episode_range(&self, i: usize) -> std::ops::Range<usize> {
        let start = if i == 0 { 0 } else { self.episode_ends[i - 1] };
        start..self.episode_ends[i]
    }

    /// The zarr groups, in order (one for a plain dataset).
    pub fn groups(&self) -> impl Iterator<Item = &Path> {
        self.groups.iter().map(|(p, _)| p.as_path())
    }

    /// The group episode `i` is stored in, and its first row there.
    fn locate(&self, i: usize) -> (&Path, usize) {
        let k = self.groups.partition_point(|&(_, first)| first <= i).saturating_sub(1);
        let (path, first) = &self.groups[k];
        let group_start = if *first == 0 { 0 } else { self.episode_ends[first - 1] };
        (path, self.episode_range(i).start - group_start)
    }

    /// An optional per-step scalar array `data/<name>`, through every group.
    ///
    /// # Errors
    /// [`ReplayError`] if it cannot be read, has the wrong length, or only some groups
    /// have it.
    pub fn extra(&self, name: &str) -> Result<Option<Vec<f64>>, ReplayError> {
        let present: Vec<bool> =
            self.groups().map(|g| g.join("data").join(name).join(".zarray").is_file()).collect();
        if !present.iter().any(|&p| p) {
            return Ok(None);
        }
        let mut out = Vec::with_capacity(self.steps());
        for (g, has) in self.groups().zip(present) {
            if !has {
                return Err(ReplayError::Layout {
                    path: g.to_path_buf(),
                    reason: format!("missing array data/{name}, which other groups of the folder have"),
                });
            }
            out.extend(open_array(&g.join("data").join(name), &self.attrs)?.read_f64()?);
        }
        if out.len() != self.steps() {
            return Err(ReplayError::Layout {
                path: self.path.clone(),
                reason: format!("data/{name} has {} values for {} steps", out.len(), self.steps()),
            });
        }
        Ok(Some(out))
    }

    /// The names of the optional per-step arrays under `data/` that every group has (sorted).
    ///
    /// # Errors
    /// [`ReplayError::Io`] if a `data/` cannot be listed.
    pub fn extra_names(&self) -> Result<Vec<String>, ReplayError> {
        let mut common: Option<Vec<String>> = None;
        for g in self.groups() {
            let dir = g.join("data");
            let entries =
                fs::read_dir(&dir).map_err(|source| ReplayError::Io { path: dir.clone(), source })?;
            let mut names: Vec<String> = entries
                .filter_map(Result::ok)
                .filter(|e| e.path().join(".zarray").is_file())
                .filter_map(|e| e.file_name().into_string().ok())
                .filter(|n| !["img", "action", "state"].contains(&n.as_str()))
                .collect();
            names.sort();
            common = Some(match common {
                None => names,
                Some(c) => c.into_iter().filter(|n| names.contains(n)).collect(),
            });
        }
        Ok(common.unwrap_or_default())
    }

    /// The shapes of this dataset's arrays, its extras included.
    ///
    /// # Errors
    /// As [`Self::extra_names`].
    pub fn spec(&self) -> Result<ReplaySpec, ReplayError> {
        let s = self.img.shape();
        Ok(ReplaySpec {
            image_hw: [s[1], s[2]],
            action_dim: self.action.row_len(),
            state_dim: self.state.row_len(),
            extras: self.extra_names()?,
        })
    }

    /// Episode `i`'s arrays, with the named extras in the given order.
    ///
    /// # Errors
    /// [`ReplayError`] for unreadable chunks or a missing extra.
    pub fn read_episode(&self, i: usize, extras: &[String]) -> Result<EpisodeArrays, ReplayError> {
        let rg = self.episode_range(i);
        let floats = |c: &Column| -> Result<Vec<f32>, ReplayError> {
            Ok(c.read_rows_f64(rg.start, rg.end)?.into_iter().map(|v| v as f32).collect())
        };
        let mut ep = EpisodeArrays {
            img: self.img.read_rows(rg.start, rg.end)?,
            action: floats(&self.action)?,
            state: floats(&self.state)?,
            extras: Vec::with_capacity(extras.len()),
        };
        let (group, local) = self.locate(i);
        for name in extras {
            let p = group.join("data").join(name);
            if !p.join(".zarray").is_file() {
                return Err(ReplayError::Layout {
                    path: group.to_path_buf(),
                    reason: format!("missing array data/{name}"),
                });
            }
            let a = open_array(&p, &self.attrs)?;
            let raw = a.read_rows(local, local + rg.len())?;
            ep.extras.push(crate::zarr::bytes_to_f64(&raw, a.dtype).into_iter().map(|v| v as f32).collect());
        }
        Ok(ep)
    }
}
