//! The user's own floor plans (`--plan FILE`, `--plans-from DIR|FILE...`): reading a room
//! outline from our JSON, GeoJSON or DXF into a validated, centred [`FloorPlan`].
//!
//! Formats (`docs/PLANS.md`):
//! - **our JSON** `{"vertices": [[x, y], ...]}` (optional `"name"`), metres;
//! - **GeoJSON** a `Polygon`, a `Feature` with a Polygon geometry, or a `FeatureCollection`
//!   of them (one room per feature); the outer ring is the room, inner rings are its
//!   columns; `LineString` features with `"kind": "door"` (or IMDF `"feature_type":
//!   "opening"`) are doors; coordinates are metres in a projected frame (longitude /
//!   latitude is refused);
//! - **DXF** closed `LWPOLYLINE` / `POLYLINE` entities (closed flag, or first vertex equal to
//!   the last) on the layer named by `--layer`, or on the only layer that holds any (layers
//!   named `*COLUMN*` and `*DOOR*` aside); closed polylines on a `*COLUMN*` layer are
//!   columns of the room around them, `LINE`s and two-vertex polylines on a `*DOOR*` layer
//!   are doors; units from `$INSUNITS` when set (unitless = metres). Arc segments (bulges)
//!   are refused.
//!
//! A door belongs to every room whose outline it lies on within [`DOOR_TOLERANCE`] (a door
//! may name its room with a `"room"` property, as `--room` names one); columns and doors go
//! through the same shift and scale as the outline ([`features`]).
//!
//! `--units mm|cm|m` overrides the file's units. A `.json` file is GeoJSON when its top-level
//! object has a `"type"` member. The closing vertex of a ring (equal to the first) is
//! dropped; either orientation is accepted. Every rejection is a [`PlanFileError`] whose
//! one-line message starts with the file (and room) and names the vertex or entity at
//! fault; nothing here panics on bad input.
//!
//! The GeoJSON and DXF readers are `from_geojson` and `from_dxf`; this module validates and
//! centres what they (and our JSON reader) return.

mod admissible;
mod features;
mod from_dxf;
mod from_geojson;

pub use features::DOOR_TOLERANCE;
use features::{with_features, RawDoor};

use activesense_core::episode::AgentKind;
use activesense_core::episode::Termination;
use activesense_core::episode::{EpisodeConfig, EpisodeParams};
use activesense_core::pipeline::runner::EpisodeRunner;
use activesense_core::world::geometry::v2;
use activesense_core::{FloorPlan, PlanError, Pose2, MAX_VERTICES};
use from_dxf::dxf_rooms;
use from_geojson::geojson_rooms;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};

/// Length unit of a plan file's coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Units {
    /// Millimetres.
    Mm,
    /// Centimetres.
    Cm,
    /// Metres (the default).
    M,
}

impl Units {
    /// Metres per unit.
    pub fn scale(self) -> f64 {
        match self {
            Units::Mm => 0.001,
            Units::Cm => 0.01,
            Units::M => 1.0,
        }
    }

    /// `mm`, `cm` or `m`.
    pub fn name(self) -> &'static str {
        match self {
            Units::Mm => "mm",
            Units::Cm => "cm",
            Units::M => "m",
        }
    }
}

/// Command-line parser for `--units`.
pub fn parse_units(s: &str) -> Result<Units, String> {
    match s {
        "mm" => Ok(Units::Mm),
        "cm" => Ok(Units::Cm),
        "m" => Ok(Units::M),
        _ => Err(format!("unknown unit '{s}' (expected mm, cm or m)")),
    }
}

/// How to read plan files.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Overrides the file's units (`--units`).
    pub units: Option<Units>,
    /// DXF layer holding the room outlines (`--layer`).
    pub layer: Option<String>,
    /// Which room of a multi-room file `load_plan` takes: its name or 0-based index
    /// (`--room`).
    pub room: Option<String>,
}

/// A user's room: its name (file name, and `#room` inside a multi-room file) and the
/// validated model-frame plan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NamedPlan {
    /// `file.ext` or `file.ext#room`.
    pub name: String,
    /// The plan, centred on its perimeter centroid (the model frame).
    pub plan: FloorPlan,
    /// Where the model frame lies in the file's own coordinates (what the answer is
    /// printed in).
    #[serde(default)]
    pub frame: PlanFrame,
}

/// Where the model frame (metres, origin at the perimeter centroid) lies in a plan file's
/// own coordinates: the shifts [`load_rooms`] applies, kept in f64 so that an answer can be
/// given back in the file's units and axes (national-grid coordinates keep their
/// millimetres). A plan point `p` (file units) is the model point
/// `(p − bbox_centre)·scale − centroid`; [`PlanFrame::to_plan`] undoes it. The axes are the
/// file's (no rotation, no mirroring), so headings are the same in both frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanFrame {
    /// Name of the file's length unit (`m`, `mm`, `cm`, or a DXF `$INSUNITS` unit such as
    /// `ft`).
    pub unit: String,
    /// Metres per file unit.
    pub scale: f64,
    /// The bounding-box centre subtracted first, in file units (f64, before going to f32).
    pub bbox_centre: [f64; 2],
    /// The perimeter centroid of the shifted, scaled outline that
    /// [`FloorPlan::centered`] then subtracted (m).
    pub centroid: [f64; 2],
}

impl Default for PlanFrame {
    /// The model frame itself (generated plans): metres, no shift.
    fn default() -> Self {
        PlanFrame {
            unit: "m".to_string(),
            scale: 1.0,
            bbox_centre: [0.0; 2],
            centroid: [0.0; 2],
        }
    }
}

impl PlanFrame {
    /// A model-frame point (m) in the file's coordinates (file units).
    pub fn to_plan(&self, model: [f64; 2]) -> [f64; 2] {
        let s = self.scale;
        [
            (model[0] + self.centroid[0]) / s + self.bbox_centre[0],
            (model[1] + self.centroid[1]) / s + self.bbox_centre[1],
        ]
    }

    /// A point in the file's coordinates (file units) in the model frame (m).
    pub fn to_model(&self, plan: [f64; 2]) -> [f64; 2] {
        let s = self.scale;
        [
            (plan[0] - self.bbox_centre[0]) * s - self.centroid[0],
            (plan[1] - self.bbox_centre[1]) * s - self.centroid[1],
        ]
    }

    /// A length in metres in file units.
    pub fn length_to_plan(&self, metres: f64) -> f64 {
        metres / self.scale
    }
}

impl NamedPlan {
    /// The plan seed an episode in this room uses for its seed derivation (the world and
    /// agent streams): FNV-1a of the name, so the same room gets the same placement and
    /// noise whatever else is in the directory.
    pub fn seed(&self) -> u32 {
        self.name.bytes().fold(0x811c_9dc5u32, |h, b| {
            (h ^ b as u32).wrapping_mul(0x0100_0193)
        })
    }
}

/// A loaded room with the remarks made while reading it (holes ignored, units used).
#[derive(Clone, Debug)]
pub struct LoadedPlan {
    /// The room.
    pub plan: NamedPlan,
    /// Warnings to show the user.
    pub warnings: Vec<String>,
}

/// Why a plan file was refused: the file, the room inside it (if any) and the reason.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanFileError {
    /// The file.
    pub path: PathBuf,
    /// The room (feature or entity) inside the file, when the file holds several.
    pub room: Option<String>,
    /// What is wrong.
    pub reason: String,
}

impl fmt::Display for PlanFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some(r) = &self.room {
            write!(f, " ({r})")?;
        }
        write!(f, ": {}", self.reason)
    }
}

impl std::error::Error for PlanFileError {}

fn err(path: &Path, room: Option<String>, reason: impl Into<String>) -> PlanFileError {
    PlanFileError {
        path: path.to_path_buf(),
        room,
        reason: reason.into(),
    }
}

/// The plan-reading options shared by `episode`, `eval`, `sim` and `serial run`.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct PlanReadArgs {
    /// Units of the plan files' coordinates, overriding the file (default: metres; DXF:
    /// its $INSUNITS when set).
    #[arg(long, value_parser = parse_units)]
    pub units: Option<Units>,
    /// DXF layer holding the room outlines (default: the only layer with closed polylines).
    #[arg(long)]
    pub layer: Option<String>,
    /// With --plan: the room of a multi-room file (its name or 0-based index).
    #[arg(long)]
    pub room: Option<String>,
}

impl PlanReadArgs {
    /// As [`LoadOptions`].
    pub fn options(&self) -> LoadOptions {
        LoadOptions {
            units: self.units,
            layer: self.layer.clone(),
            room: self.room.clone(),
        }
    }
}

/// The rooms a command runs in: the one of `plan` (`--plan`), or every room of
/// `plans_from` (`--plans-from`; refused files are listed on stderr and returned), or `None`
/// for generated plans. Warnings go to stderr. Fails when no room is usable.
pub fn rooms_for_command(
    plan: Option<&Path>,
    plans_from: &[PathBuf],
    read: &PlanReadArgs,
) -> anyhow::Result<Option<(Vec<NamedPlan>, Vec<PlanFileError>)>> {
    let opts = read.options();
    let (good, bad) = match (plan, plans_from.is_empty()) {
        (Some(_), false) => anyhow::bail!("give either --plan or --plans-from, not both"),
        (Some(p), true) => (vec![load_plan(p, &opts)?], Vec::new()),
        (None, false) => load_plans_from(plans_from, &opts),
        (None, true) => return Ok(None),
    };
    for g in &good {
        for w in &g.warnings {
            eprintln!("warning: {}: {w}", g.plan.name);
        }
    }
    for b in &bad {
        eprintln!("refused: {b}");
    }
    if good.is_empty() {
        anyhow::bail!(
            "no usable floor plan ({} file(s) refused, listed above)",
            bad.len()
        );
    }
    if !bad.is_empty() {
        eprintln!(
            "{} room(s) loaded, {} file(s) refused",
            good.len(),
            bad.len()
        );
    }
    Ok(Some((good.into_iter().map(|g| g.plan).collect(), bad)))
}

/// File formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Json,
    GeoJson,
    Dxf,
}

fn format_of(path: &Path) -> Option<Format> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    match ext.as_str() {
        "json" => Some(Format::Json),
        "geojson" => Some(Format::GeoJson),
        "dxf" => Some(Format::Dxf),
        _ => None,
    }
}

/// One outline as read from a file, before validation: its name inside a multi-room file,
/// vertices in file units, its columns (file units), warnings.
struct RawRoom {
    name: Option<String>,
    vertices: Vec<[f64; 2]>,
    columns: Vec<Vec<[f64; 2]>>,
    warnings: Vec<String>,
}

/// Every room of a plan file, in file order.
pub fn load_rooms(path: &Path, opts: &LoadOptions) -> Result<Vec<LoadedPlan>, PlanFileError> {
    let format = format_of(path).ok_or_else(|| {
        err(
            path,
            None,
            "unknown plan format (expected .json, .geojson or .dxf)",
        )
    })?;
    let (rooms, doors, file_units) = match format {
        Format::Json | Format::GeoJson => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| err(path, None, format!("cannot read: {e}")))?;
            let value: serde_json::Value = serde_json::from_str(&text)
                .map_err(|e| err(path, None, format!("not valid JSON: {e}")))?;
            let geo = format == Format::GeoJson || value.get("type").is_some();
            let (rooms, doors) = if geo {
                geojson_rooms(path, &value)?
            } else {
                (vec![our_json_room(path, &value)?], Vec::new())
            };
            (rooms, doors, None)
        }
        Format::Dxf => dxf_rooms(path, opts)?,
    };
    let units = opts.units.map(|u| (u.scale(), u.name()));
    let mut notes = Vec::new();
    if let (None, Some((_, name))) = (units, file_units) {
        notes.push(format!("coordinates in {name} ($INSUNITS)"));
    }
    let (scale, unit_name) = units.or(file_units).unwrap_or((1.0, "m"));
    let stem = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string());
    let many = rooms.len() > 1;
    let mut out = Vec::with_capacity(rooms.len());
    let mut door_used = vec![false; doors.len()];
    for (i, raw) in rooms.into_iter().enumerate() {
        let label = raw.name.clone().unwrap_or_else(|| format!("room {i}"));
        let room = many.then(|| label.clone());
        // The doors that may be this room's: those naming it, and those naming no room.
        let candidates: Vec<usize> = (0..doors.len())
            .filter(|&d| {
                doors[d].room.as_ref().is_none_or(|r| {
                    raw.name.as_deref() == Some(r.as_str()) || r.parse::<usize>() == Ok(i)
                })
            })
            .collect();
        let cand: Vec<&RawDoor> = candidates.iter().map(|&d| &doors[d]).collect();
        let (plan, frame, remarks, used) =
            validate(path, room.clone(), &raw, &cand, scale, unit_name)?;
        for (k, &d) in candidates.iter().enumerate() {
            door_used[d] |= used.get(k).copied().unwrap_or(false);
        }
        let name = if many {
            format!(
                "{stem}#{}",
                raw.name.clone().unwrap_or_else(|| i.to_string())
            )
        } else {
            stem.clone()
        };
        let mut warnings = raw.warnings;
        warnings.extend(notes.iter().cloned());
        warnings.extend(remarks);
        out.push(LoadedPlan {
            plan: NamedPlan { name, plan, frame },
            warnings,
        });
    }
    if let Some(d) = door_used.iter().position(|u| !u) {
        return Err(err(
            path,
            None,
            format!(
                "{} lies on no room's outline (within {} cm)",
                doors[d].label,
                DOOR_TOLERANCE * 100.0
            ),
        ));
    }
    Ok(out)
}

/// The one room of a plan file (`--plan`): a file with several rooms needs
/// `opts.room` (a room name or 0-based index).
pub fn load_plan(path: &Path, opts: &LoadOptions) -> Result<LoadedPlan, PlanFileError> {
    let mut rooms = load_rooms(path, opts)?;
    let names = |rooms: &[LoadedPlan]| {
        rooms
            .iter()
            .map(|r| r.plan.name.clone())
            .collect::<Vec<_>>()
            .join(", ")
    };
    match &opts.room {
        None if rooms.len() == 1 => Ok(rooms.remove(0)),
        None => Err(err(
            path,
            None,
            format!(
                "holds {} rooms ({}); choose one with --room NAME|INDEX, or evaluate all with --plans-from",
                rooms.len(),
                names(&rooms)
            ),
        )),
        Some(r) => {
            let by_name = rooms
                .iter()
                .position(|p| p.plan.name.rsplit_once('#').map(|x| x.1) == Some(r.as_str()));
            let by_index = r.parse::<usize>().ok().filter(|i| *i < rooms.len());
            match by_name.or(by_index) {
                Some(i) => Ok(rooms.swap_remove(i)),
                None => Err(err(
                    path,
                    None,
                    format!("no room '{r}' (rooms: {})", names(&rooms)),
                )),
            }
        }
    }
}

/// Every room of `paths` (files, and directories whose `.json` / `.geojson` / `.dxf`
/// files are read in name order, not recursively), and the files that were refused with
/// why. A bad file never stops the others.
pub fn load_plans_from(
    paths: &[PathBuf],
    opts: &LoadOptions,
) -> (Vec<LoadedPlan>, Vec<PlanFileError>) {
    let mut files = Vec::new();
    let mut bad = Vec::new();
    for p in paths {
        if p.is_dir() {
            match std::fs::read_dir(p) {
                Ok(rd) => {
                    let mut found: Vec<PathBuf> = rd
                        .filter_map(|e| e.ok().map(|e| e.path()))
                        .filter(|f| !f.is_dir() && format_of(f).is_some())
                        .collect();
                    found.sort();
                    if found.is_empty() {
                        bad.push(err(
                            p,
                            None,
                            "no .json, .geojson or .dxf files in directory",
                        ));
                    }
                    files.extend(found);
                }
                Err(e) => bad.push(err(p, None, format!("cannot read directory: {e}"))),
            }
        } else {
            files.push(p.clone());
        }
    }
    let mut good = Vec::new();
    for f in files {
        match load_rooms(&f, opts) {
            Ok(rooms) => good.extend(rooms),
            Err(e) => bad.push(e),
        }
    }
    (good, bad)
}

/// What [`validate`] returns: the plan, where its model frame lies in the file's
/// coordinates, the admissibility warnings, and which candidate doors lie on the room.
type Validated = (FloorPlan, PlanFrame, Vec<String>, Vec<bool>);

/// Scales, de-duplicates the closing vertex, orients and validates one outline, adds its
/// columns and the candidate doors lying on it ([`features`]), and checks that the
/// instrument can localize in it ([`admissible`]). Errors name outline vertices by their
/// index in the file (0-based) and their coordinates.
fn validate(
    path: &Path,
    room: Option<String>,
    raw: &RawRoom,
    doors: &[&RawDoor],
    scale: f64,
    unit_name: &str,
) -> Result<Validated, PlanFileError> {
    let e = |reason: String| err(path, room.clone(), reason);
    let mut v: Vec<[f64; 2]> = raw.vertices.to_vec();
    if v.len() >= 2 && v.first() == v.last() {
        v.pop();
    }
    let n = v.len();
    if n < 3 {
        return Err(e(format!("{n} distinct vertices; a room needs at least 3")));
    }
    if n > MAX_VERTICES {
        return Err(e(format!(
            "{n} vertices; a room may have at most {MAX_VERTICES} (docs/PLANS.md, \"Limits\")"
        )));
    }
    if let Some(i) = v
        .iter()
        .position(|p| !p[0].is_finite() || !p[1].is_finite())
    {
        return Err(e(format!("vertex {i} has a non-finite coordinate")));
    }
    let coords = |i: usize| format!("({}, {})", v[i % n][0], v[i % n][1]);
    // Orientation from the file's own coordinates (f64), so that indices in errors are the
    // file's.
    let area2: f64 = (0..n)
        .map(|i| {
            let (a, b) = (v[i], v[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum();
    let reversed = area2 < 0.0;
    let (lo, hi) = v
        .iter()
        .fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            )
        });
    let order: Vec<usize> = if reversed {
        (0..n).rev().collect()
    } else {
        (0..n).collect()
    };
    // Subtract the bounding-box centre before going to f32, so that surveyed coordinates
    // far from the origin (national grids) keep their centimetres.
    let cx = 0.5 * (lo[0] + hi[0]);
    let cy = 0.5 * (lo[1] + hi[1]);
    let pts: Vec<_> = order
        .iter()
        .map(|&i| {
            v2(
                ((v[i][0] - cx) * scale) as f32,
                ((v[i][1] - cy) * scale) as f32,
            )
        })
        .collect();
    // Vertex index k of the oriented outline is file vertex order[k]; edge k runs from
    // order[k] to order[k + 1].
    let fv = |k: u8| order[k as usize % n];
    let edge = |k: u8| {
        let (a, b) = (fv(k), order[(k as usize + 1) % n]);
        format!("edge {a}–{b} {} → {}", coords(a), coords(b))
    };
    let outline = FloorPlan::new(&pts)
        .map_err(|pe| {
            e(match pe {
                PlanError::TooFewVertices | PlanError::TooManyVertices => pe.to_string(),
                PlanError::NonFiniteCoordinate(k) => {
                    format!("vertex {} has a non-finite coordinate", fv(k))
                }
                PlanError::BadExtent => {
                    let (w, h) = ((hi[0] - lo[0]) * scale, (hi[1] - lo[1]) * scale);
                    let hint = if w > 500.0 || h > 500.0 {
                        if unit_name == "m" {
                            "; are the coordinates millimetres? try --units mm"
                        } else {
                            ""
                        }
                    } else if lo[0] >= -180.0 && hi[0] <= 180.0 && lo[1] >= -90.0 && hi[1] <= 90.0 && w < 0.5 && h < 0.5 {
                        "; longitude/latitude degrees are not supported, project the plan to metres first"
                    } else {
                        ""
                    };
                    format!(
                        "the room is {w:.3} m × {h:.3} m ({unit_name} coordinates); each side must be 0.5–500 m{hint}"
                    )
                }
                PlanError::ZeroLengthEdge(k) => {
                    format!("{} is shorter than 1 cm (duplicate vertex?)", edge(k))
                }
                PlanError::CollinearVertex(k) => format!(
                    "vertex {} {} lies on the line through its neighbours (remove it)",
                    fv(k),
                    coords(fv(k))
                ),
                PlanError::SelfIntersection(a, b) => format!(
                    "the outline crosses itself: {} touches {}",
                    edge(a),
                    edge(b)
                ),
                PlanError::Clockwise => "the outline has zero area".to_string(),
                other => other.to_string(),
            })
        })?;
    let (plan, used) = if raw.columns.is_empty() && doors.is_empty() {
        (outline, Vec::new())
    } else {
        with_features(&pts, &raw.columns, doors, [cx, cy], scale).map_err(e)?
    };
    // The perimeter centroid `centered` subtracts, kept for the answer's frame.
    let c = plan.perimeter_centroid();
    let centroid = [c.x as f64, c.y as f64];
    let plan = plan.centered();
    fits_pipeline(&plan).map_err(e)?;
    let remarks = admissible::check(&plan).map_err(e)?;
    let frame = PlanFrame {
        unit: unit_name.to_string(),
        scale,
        bbox_centre: [cx, cy],
        centroid,
    };
    Ok((plan, frame, remarks, used))
}

/// Starts an episode in `plan` with both rotation settings, so that a plan the pipeline
/// cannot take is refused here and never reaches an episode.
fn fits_pipeline(plan: &FloorPlan) -> Result<(), String> {
    let mut runner = Box::new(EpisodeRunner::new_empty());
    for rot_bins in [1u8, 10] {
        // No `EpisodeSpec` here (it would import this module back): the core's type as is.
        let params = EpisodeParams {
            agent: AgentKind::Blind0,
            seed: 0,
            rot_bins,
            known_heading: (rot_bins == 1).then_some(0.0),
            ground_truth: Some(Pose2::new(0.0, 0.0, 0.0)),
            initial_scan: 0,
            termination: Termination::Oracle,
            config: EpisodeConfig::default(),
        };
        runner
            .start(plan, &params)
            .map_err(|e| format!("the localizer cannot take this room: {e:?}"))?;
    }
    Ok(())
}

fn our_json_room(path: &Path, value: &serde_json::Value) -> Result<RawRoom, PlanFileError> {
    let verts = value.get("vertices").ok_or_else(|| {
        err(
            path,
            None,
            "no \"vertices\" member: expected {\"vertices\": [[x, y], ...]} or a GeoJSON object with a \"type\"",
        )
    })?;
    let vertices =
        coords_array(verts).map_err(|r| err(path, None, format!("\"vertices\": {r}")))?;
    Ok(RawRoom {
        name: value
            .get("name")
            .and_then(|n| n.as_str())
            .map(str::to_string),
        vertices,
        columns: Vec::new(),
        warnings: Vec::new(),
    })
}

/// `[[x, y], ...]` (a third coordinate is ignored, as GeoJSON allows).
fn coords_array(v: &serde_json::Value) -> Result<Vec<[f64; 2]>, String> {
    let arr = v.as_array().ok_or("expected an array of [x, y] pairs")?;
    arr.iter()
        .enumerate()
        .map(|(i, p)| {
            let xy = p.as_array().filter(|a| a.len() >= 2);
            match xy.map(|a| (a[0].as_f64(), a[1].as_f64())) {
                Some((Some(x), Some(y))) => Ok([x, y]),
                _ => Err(format!("vertex {i} is not an [x, y] pair of numbers: {p}")),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An L-shaped room (metres, counter-clockwise).
    pub const L_ROOM: [[f64; 2]; 6] = [
        [0.0, 0.0],
        [6.0, 0.0],
        [6.0, 3.0],
        [2.5, 3.0],
        [2.5, 5.0],
        [0.0, 5.0],
    ];

    fn dir(tag: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("activesense-planfile-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn expected() -> FloorPlan {
        let pts: Vec<_> = L_ROOM
            .iter()
            .map(|p| v2(p[0] as f32, p[1] as f32))
            .collect();
        FloorPlan::new(&pts).unwrap().centered()
    }

    fn assert_same(plan: &FloorPlan) {
        let e = expected();
        assert_eq!(plan.len(), e.len());
        // Same vertices up to the starting vertex.
        let start = (0..plan.len())
            .find(|&s| (plan.vertex(s) - e.vertex(0)).norm() < 1e-4)
            .expect("first vertex present");
        for i in 0..e.len() {
            let d = (plan.vertex(start + i) - e.vertex(i)).norm();
            assert!(
                d < 1e-4,
                "vertex {i}: {:?} vs {:?}",
                plan.vertex(start + i),
                e.vertex(i)
            );
        }
    }

    fn dxf_text(layer_polys: &[(&str, &[[f64; 2]], bool)], insunits: Option<i16>) -> String {
        let mut s = String::new();
        if let Some(u) = insunits {
            s += &format!(
                "0\nSECTION\n2\nHEADER\n9\n$ACADVER\n1\nAC1015\n9\n$INSUNITS\n70\n{u}\n0\nENDSEC\n"
            );
        }
        s += "0\nSECTION\n2\nENTITIES\n";
        for (h, (layer, pts, closed)) in layer_polys.iter().enumerate() {
            s += &format!(
                "0\nLWPOLYLINE\n5\n{:X}\n8\n{layer}\n100\nAcDbPolyline\n90\n{}\n70\n{}\n",
                h + 0x20,
                pts.len(),
                if *closed { 1 } else { 0 }
            );
            for p in pts.iter() {
                s += &format!("10\n{}\n20\n{}\n", p[0], p[1]);
            }
        }
        s += "0\nENDSEC\n0\nEOF\n";
        s
    }

    #[test]
    fn each_format_round_trips_the_l_room() {
        let d = dir("rt");
        let opts = LoadOptions::default();
        let json = d.join("l.json");
        std::fs::write(&json, serde_json::json!({ "vertices": L_ROOM }).to_string()).unwrap();
        assert_same(&load_plan(&json, &opts).unwrap().plan.plan);
        // GeoJSON: clockwise, closed ring, in millimetres.
        let mut ring: Vec<[f64; 2]> = L_ROOM
            .iter()
            .rev()
            .map(|p| [p[0] * 1000.0, p[1] * 1000.0])
            .collect();
        ring.push(ring[0]);
        let geo = d.join("l.geojson");
        std::fs::write(
            &geo,
            serde_json::json!({"type": "Polygon", "coordinates": [ring]}).to_string(),
        )
        .unwrap();
        let mm = LoadOptions {
            units: Some(Units::Mm),
            ..Default::default()
        };
        assert_same(&load_plan(&geo, &mm).unwrap().plan.plan);
        // DXF in centimetres ($INSUNITS = 5), far from the origin.
        let cm: Vec<[f64; 2]> = L_ROOM
            .iter()
            .map(|p| [p[0] * 100.0 + 5.0e6, p[1] * 100.0 + 2.0e6])
            .collect();
        let dxf = d.join("l.dxf");
        std::fs::write(&dxf, dxf_text(&[("walls", &cm, true)], Some(5))).unwrap();
        let loaded = load_plan(&dxf, &opts).unwrap();
        assert_same(&loaded.plan.plan);
        assert_eq!(loaded.plan.name, "l.dxf");
    }

    #[test]
    fn the_frame_gives_back_national_grid_coordinates() {
        // The L-room at E ≈ 2 600 123, N ≈ 1 200 456 (m), and in millimetres far out.
        let d = dir("frame");
        let (e0, n0) = (2_600_123.0, 1_200_456.0);
        let grid: Vec<[f64; 2]> = L_ROOM.iter().map(|p| [p[0] + e0, p[1] + n0]).collect();
        let json = d.join("grid.json");
        std::fs::write(&json, serde_json::json!({ "vertices": grid }).to_string()).unwrap();
        let named = load_plan(&json, &LoadOptions::default()).unwrap().plan;
        assert_eq!((named.frame.unit.as_str(), named.frame.scale), ("m", 1.0));
        // Every model vertex maps back onto its file vertex to well under a millimetre.
        for k in 0..named.plan.len() {
            let m = named.plan.vertex(k);
            let p = named.frame.to_plan([m.x as f64, m.y as f64]);
            let near = grid
                .iter()
                .map(|g| ((g[0] - p[0]).powi(2) + (g[1] - p[1]).powi(2)).sqrt())
                .fold(f64::MAX, f64::min);
            assert!(near < 1e-4, "vertex {k}: {p:?}");
            let back = named.frame.to_model(p);
            assert!((back[0] - m.x as f64).abs() < 1e-9 && (back[1] - m.y as f64).abs() < 1e-9);
        }
        let mm: Vec<[f64; 2]> = grid
            .iter()
            .map(|p| [p[0] * 1000.0, p[1] * 1000.0])
            .collect();
        let dxf = d.join("grid-mm.dxf");
        std::fs::write(&dxf, dxf_text(&[("walls", &mm, true)], Some(4))).unwrap();
        let named = load_plan(&dxf, &LoadOptions::default()).unwrap().plan;
        assert_eq!(named.frame.unit, "mm");
        let m = named.plan.vertex(0);
        let p = named.frame.to_plan([m.x as f64, m.y as f64]);
        let near = mm
            .iter()
            .map(|g| ((g[0] - p[0]).powi(2) + (g[1] - p[1]).powi(2)).sqrt())
            .fold(f64::MAX, f64::min);
        assert!(near < 0.1, "{p:?} (mm)");
        assert!((named.frame.length_to_plan(0.001) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn errors_name_file_and_vertex() {
        let d = dir("err");
        let opts = LoadOptions::default();
        let bow = d.join("bow.json");
        std::fs::write(&bow, r#"{"vertices": [[0,0],[4,0],[0,3],[4,3]]}"#).unwrap();
        let e = load_plan(&bow, &opts).unwrap_err().to_string();
        assert!(e.starts_with(&bow.display().to_string()), "{e}");
        assert!(
            e.contains("crosses itself")
                && e.contains("edge 1–2 (4, 0) → (0, 3)")
                && e.contains("edge 3–0"),
            "{e}"
        );
        // Clockwise input: indices are still the file's.
        let col = d.join("col.json");
        std::fs::write(&col, r#"{"vertices": [[0,0],[0,3],[4,3],[4,0],[2,0]]}"#).unwrap();
        let e = load_plan(&col, &opts).unwrap_err().to_string();
        assert!(e.contains("vertex 4 (2, 0) lies on the line"), "{e}");
        let huge = d.join("huge.json");
        std::fs::write(
            &huge,
            r#"{"vertices": [[0,0],[4000,0],[4000,3000],[0,3000]]}"#,
        )
        .unwrap();
        let e = load_plan(&huge, &opts).unwrap_err().to_string();
        assert!(e.contains("--units mm"), "{e}");
        let mm = LoadOptions {
            units: Some(Units::Mm),
            ..Default::default()
        };
        assert_eq!(load_plan(&huge, &mm).unwrap().plan.plan.len(), 4);
    }

    #[test]
    fn dxf_layers_and_bulges() {
        let d = dir("dxf");
        let opts = LoadOptions::default();
        let rect: &[[f64; 2]] = &[[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]];
        let two = d.join("two.dxf");
        std::fs::write(
            &two,
            dxf_text(&[("a", rect, true), ("b", &L_ROOM, true)], None),
        )
        .unwrap();
        let e = load_plan(&two, &opts).unwrap_err().to_string();
        assert!(e.contains("several layers (a, b)"), "{e}");
        let b = LoadOptions {
            layer: Some("b".into()),
            ..Default::default()
        };
        assert_same(&load_plan(&two, &b).unwrap().plan.plan);
        let open = d.join("open.dxf");
        std::fs::write(&open, dxf_text(&[("walls", rect, false)], None)).unwrap();
        let e = load_plan(&open, &opts).unwrap_err().to_string();
        assert!(e.contains("LWPOLYLINE 20 on layer 'walls' is open"), "{e}");
        let arc = d.join("arc.dxf");
        let text =
            dxf_text(&[("walls", rect, true)], None).replacen("20\n0\n", "20\n0\n42\n0.5\n", 1);
        std::fs::write(&arc, text).unwrap();
        let e = load_plan(&arc, &opts).unwrap_err().to_string();
        assert!(e.contains("vertex 0 starts an arc"), "{e}");
    }

    #[test]
    fn dxf_polyline_and_closing_vertex() {
        let d = dir("poly");
        let opts = LoadOptions::default();
        // An old-style POLYLINE (VERTEX entities, SEQEND), closed by its flag.
        let mut t = String::from(
            "0\nSECTION\n2\nENTITIES\n0\nPOLYLINE\n5\n50\n8\nROOMS\n66\n1\n10\n0\n20\n0\n30\n0\n70\n1\n",
        );
        for p in L_ROOM {
            t += &format!("0\nVERTEX\n8\nROOMS\n10\n{}\n20\n{}\n30\n0\n", p[0], p[1]);
        }
        t += "0\nSEQEND\n8\nROOMS\n0\nENDSEC\n0\nEOF\n";
        let poly = d.join("poly.dxf");
        std::fs::write(&poly, t).unwrap();
        assert_same(&load_plan(&poly, &opts).unwrap().plan.plan);
        // An LWPOLYLINE without the closed flag whose last vertex repeats the first.
        let mut ring = L_ROOM.to_vec();
        ring.push(ring[0]);
        let lw = d.join("ring.dxf");
        std::fs::write(&lw, dxf_text(&[("0", &ring, false)], Some(6))).unwrap();
        assert_same(&load_plan(&lw, &opts).unwrap().plan.plan);
        // Two rooms on one layer: --plan needs --room, load_rooms names them by index.
        let rect: &[[f64; 2]] = &[[10.0, 0.0], [14.0, 0.0], [14.0, 3.0], [10.0, 3.0]];
        let two = d.join("two-rooms.dxf");
        std::fs::write(
            &two,
            dxf_text(&[("R", &L_ROOM, true), ("R", rect, true)], None),
        )
        .unwrap();
        let rooms = load_rooms(&two, &opts).unwrap();
        let names: Vec<_> = rooms.iter().map(|r| r.plan.name.as_str()).collect();
        assert_eq!(names, ["two-rooms.dxf#0", "two-rooms.dxf#1"]);
        assert!(load_plan(&two, &opts)
            .unwrap_err()
            .reason
            .contains("holds 2 rooms"));
        let first = LoadOptions {
            room: Some("0".into()),
            ..Default::default()
        };
        assert_same(&load_plan(&two, &first).unwrap().plan.plan);
    }

    #[test]
    fn file_seeds_are_stable() {
        let p = NamedPlan {
            name: "office.json".into(),
            plan: expected(),
            frame: PlanFrame::default(),
        };
        assert_eq!(
            p.seed(),
            NamedPlan {
                name: "office.json".into(),
                plan: expected(),
                frame: PlanFrame::default(),
            }
            .seed()
        );
        assert_ne!(
            p.seed(),
            NamedPlan {
                name: "office2.json".into(),
                plan: expected(),
                frame: PlanFrame::default(),
            }
            .seed()
        );
    }
}
