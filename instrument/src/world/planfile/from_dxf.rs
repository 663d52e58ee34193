//! The DXF reader of [`super`]: closed `LWPOLYLINE` / `POLYLINE` entities on the chosen
//! layer, units from `$INSUNITS` (arc segments refused). Layers whose name contains
//! `COLUMN` (any case) hold columns (closed polylines, each given to the room around it) and
//! layers whose name contains `DOOR` hold doors (`LINE`s and two-vertex polylines); neither
//! kind of layer is ever taken for the room outlines.

use super::*;

/// A layer of columns: its name contains `COLUMN` (any case).
fn is_column_layer(layer: &str) -> bool {
    layer.to_ascii_uppercase().contains("COLUMN")
}

/// A layer of doors: its name contains `DOOR` (any case).
fn is_door_layer(layer: &str) -> bool {
    layer.to_ascii_uppercase().contains("DOOR")
}

/// Crossing-number point-in-polygon in file coordinates (which room a column stands in).
fn inside(ring: &[[f64; 2]], p: [f64; 2]) -> bool {
    let n = ring.len();
    let mut c = false;
    for k in 0..n {
        let (a, b) = (ring[k], ring[(k + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
        {
            c = !c;
        }
    }
    c
}

/// Metres per unit of a DXF `$INSUNITS` value we can convert, with its name.
fn dxf_units(u: dxf::enums::Units) -> Option<Option<(f64, &'static str)>> {
    use dxf::enums::Units as U;
    Some(match u {
        U::Unitless => None,
        U::Millimeters => Some((0.001, "mm")),
        U::Centimeters => Some((0.01, "cm")),
        U::Decimeters => Some((0.1, "dm")),
        U::Meters => Some((1.0, "m")),
        U::Inches => Some((0.0254, "in")),
        U::Feet => Some((0.3048, "ft")),
        U::USSurveyFeet => Some((1200.0 / 3937.0, "US survey ft")),
        _ => return None,
    })
}

type DxfRooms = (Vec<RawRoom>, Vec<RawDoor>, Option<(f64, &'static str)>);

pub(super) fn dxf_rooms(path: &Path, opts: &LoadOptions) -> Result<DxfRooms, PlanFileError> {
    use dxf::entities::EntityType;
    // The dxf crate reads the whole file; a read error is reported with its message.
    std::fs::metadata(path).map_err(|e| err(path, None, format!("cannot read: {e}")))?;
    let drawing = std::panic::catch_unwind(|| dxf::Drawing::load_file(path))
        .map_err(|_| {
            err(
                path,
                None,
                "not a readable DXF file (the DXF reader failed)",
            )
        })?
        .map_err(|e| err(path, None, format!("not a readable DXF file: {e}")))?;
    let units = match dxf_units(drawing.header.default_drawing_units) {
        Some(u) => u,
        None if opts.units.is_some() => None,
        None => {
            return Err(err(
                path,
                None,
                format!(
                    "$INSUNITS is {:?}, which we do not convert; give --units mm|cm|m",
                    drawing.header.default_drawing_units
                ),
            ))
        }
    };
    /// A polyline entity: layer, label for messages, vertices, closed, first vertex with a
    /// bulge, mesh.
    struct Poly {
        layer: String,
        label: String,
        vertices: Vec<[f64; 2]>,
        closed: bool,
        bulge: Option<usize>,
        mesh: bool,
    }
    let mut polys = Vec::new();
    let mut doors = Vec::new();
    for ent in drawing.entities() {
        let layer = ent.common.layer.clone();
        let handle = ent.common.handle.0;
        match &ent.specific {
            EntityType::Line(l) if is_door_layer(&layer) => doors.push(RawDoor {
                label: format!("door LINE {handle:X} on layer '{layer}'"),
                ends: [[l.p1.x, l.p1.y], [l.p2.x, l.p2.y]],
                room: None,
            }),
            EntityType::LwPolyline(p) => {
                let vertices: Vec<[f64; 2]> = p.vertices.iter().map(|v| [v.x, v.y]).collect();
                let closed =
                    p.is_closed() || (vertices.len() > 2 && vertices.first() == vertices.last());
                polys.push(Poly {
                    layer,
                    label: format!("LWPOLYLINE {handle:X} on layer '{}'", ent.common.layer),
                    bulge: p.vertices.iter().position(|v| v.bulge != 0.0),
                    vertices,
                    closed,
                    mesh: false,
                });
            }
            EntityType::Polyline(p) => {
                let vs: Vec<_> = p.vertices().collect();
                let vertices: Vec<[f64; 2]> =
                    vs.iter().map(|v| [v.location.x, v.location.y]).collect();
                let closed =
                    p.is_closed() || (vertices.len() > 2 && vertices.first() == vertices.last());
                polys.push(Poly {
                    layer,
                    label: format!("POLYLINE {handle:X} on layer '{}'", ent.common.layer),
                    bulge: vs.iter().position(|v| v.bulge != 0.0),
                    vertices,
                    closed,
                    mesh: p.is_polyface_mesh() || p.is_3d_polygon_mesh(),
                });
            }
            _ => {}
        }
    }
    let polys: Vec<Poly> = polys.into_iter().filter(|p| !p.mesh).collect();
    // Columns and doors drawn as polylines, kept apart from the outlines.
    let (features, polys): (Vec<Poly>, Vec<Poly>) = polys
        .into_iter()
        .partition(|p| is_column_layer(&p.layer) || is_door_layer(&p.layer));
    let mut columns: Vec<&Poly> = Vec::new();
    for p in &features {
        if is_door_layer(&p.layer) && p.vertices.len() == 2 && !p.closed {
            doors.push(RawDoor {
                label: format!("door {}", p.label),
                ends: [p.vertices[0], p.vertices[1]],
                room: None,
            });
        } else if is_column_layer(&p.layer) && p.closed {
            if let Some(k) = p.bulge {
                return Err(err(
                    path,
                    None,
                    format!(
                        "{}: vertex {k} starts an arc (bulge); arcs are not supported, replace them by straight segments",
                        p.label
                    ),
                ));
            }
            columns.push(p);
        } else {
            return Err(err(
                path,
                None,
                format!(
                    "{} is neither a column (a closed polyline on a COLUMN layer) nor a door (a LINE or a two-vertex polyline on a DOOR layer)",
                    p.label
                ),
            ));
        }
    }
    if polys.is_empty() {
        return Err(err(
            path,
            None,
            "no LWPOLYLINE or POLYLINE entity (draw each room as a closed polyline; blocks are not expanded)",
        ));
    }
    let on_layer: Vec<&Poly> = match &opts.layer {
        Some(l) => {
            let v: Vec<&Poly> = polys.iter().filter(|p| &p.layer == l).collect();
            if v.is_empty() {
                let mut layers: Vec<&str> = polys.iter().map(|p| p.layer.as_str()).collect();
                layers.sort();
                layers.dedup();
                return Err(err(
                    path,
                    None,
                    format!(
                        "no polyline on layer '{l}' (layers with polylines: {})",
                        layers.join(", ")
                    ),
                ));
            }
            v
        }
        None => {
            let mut layers: Vec<&str> = polys
                .iter()
                .filter(|p| p.closed)
                .map(|p| p.layer.as_str())
                .collect();
            layers.sort();
            layers.dedup();
            match layers.len() {
                0 => {
                    let p = &polys[0];
                    return Err(err(
                        path,
                        None,
                        format!(
                            "{} is open (no closed flag, and its first vertex differs from its last); no closed polyline in the file",
                            p.label
                        ),
                    ));
                }
                1 => polys.iter().filter(|p| p.layer == layers[0]).collect(),
                _ => {
                    return Err(err(
                        path,
                        None,
                        format!(
                            "closed polylines on several layers ({}); choose one with --layer NAME",
                            layers.join(", ")
                        ),
                    ))
                }
            }
        }
    };
    let mut rooms = Vec::new();
    for (i, p) in on_layer.iter().enumerate() {
        if !p.closed {
            return Err(err(
                path,
                None,
                format!(
                    "{} is open (no closed flag, and its first vertex differs from its last)",
                    p.label
                ),
            ));
        }
        if let Some(k) = p.bulge {
            return Err(err(
                path,
                None,
                format!(
                    "{}: vertex {k} starts an arc (bulge); arcs are not supported, replace them by straight segments",
                    p.label
                ),
            ));
        }
        rooms.push(RawRoom {
            name: (on_layer.len() > 1).then(|| i.to_string()),
            vertices: p.vertices.clone(),
            columns: Vec::new(),
            warnings: Vec::new(),
        });
    }
    // Each column belongs to the room its first vertex stands in.
    for c in columns {
        let first = c.vertices.first().copied().unwrap_or([f64::NAN; 2]);
        match rooms.iter_mut().find(|r| inside(&r.vertices, first)) {
            Some(r) => r.columns.push(c.vertices.clone()),
            None => {
                return Err(err(
                    path,
                    None,
                    format!("column {} stands in no room", c.label),
                ))
            }
        }
    }
    Ok((rooms, doors, units))
}
