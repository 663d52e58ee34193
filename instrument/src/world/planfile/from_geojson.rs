//! The GeoJSON reader of [`super`]: a `Polygon`, a `Feature` with a Polygon geometry, or a
//! `FeatureCollection` of them, one room per feature (the outer ring its outline, the inner
//! rings its columns; longitude / latitude refused), and the collection's doors: `LineString`
//! features with `"properties": {"kind": "door"}` or IMDF's `"feature_type": "opening"`.

use super::*;

/// The rooms and the doors of a GeoJSON file.
type GeoRooms = (Vec<RawRoom>, Vec<RawDoor>);

pub(super) fn geojson_rooms(
    path: &Path,
    value: &serde_json::Value,
) -> Result<GeoRooms, PlanFileError> {
    let ty = value.get("type").and_then(|t| t.as_str()).unwrap_or("");
    match ty {
        "FeatureCollection" => {
            let features = value
                .get("features")
                .and_then(|f| f.as_array())
                .ok_or_else(|| err(path, None, "FeatureCollection without a \"features\" array"))?;
            let mut rooms = Vec::new();
            let mut doors = Vec::new();
            for (i, f) in features.iter().enumerate() {
                let name = feature_name(f);
                let label = format!(
                    "feature {i}{}",
                    name.as_ref().map(|n| format!(" '{n}'")).unwrap_or_default()
                );
                if is_door(f) {
                    let ends =
                        door_ends(f).map_err(|reason| err(path, Some(label.clone()), reason))?;
                    let room =
                        f.get("properties")
                            .and_then(|p| p.get("room"))
                            .and_then(|r| match r {
                                serde_json::Value::String(s) => Some(s.clone()),
                                serde_json::Value::Number(n) => Some(n.to_string()),
                                _ => None,
                            });
                    doors.push(RawDoor {
                        label: format!("door ({label})"),
                        ends,
                        room,
                    });
                    continue;
                }
                let mut r = geojson_feature(f).map_err(|reason| err(path, Some(label), reason))?;
                // Rooms are numbered among the rooms (doors take no room index).
                r.name = Some(name.unwrap_or_else(|| rooms.len().to_string()));
                rooms.push(r);
            }
            if rooms.is_empty() {
                return Err(err(path, None, "FeatureCollection has no features"));
            }
            Ok((rooms, doors))
        }
        _ => geojson_feature(value)
            .map(|r| (vec![r], Vec::new()))
            .map_err(|reason| err(path, None, reason)),
    }
}

/// A door: a `LineString` feature whose properties say `"kind": "door"`, or an IMDF
/// `opening` feature (`"feature_type": "opening"`).
fn is_door(f: &serde_json::Value) -> bool {
    let kind = f
        .get("properties")
        .and_then(|p| p.get("kind"))
        .and_then(|k| k.as_str());
    let imdf = f.get("feature_type").and_then(|k| k.as_str());
    kind == Some("door") || imdf == Some("opening")
}

/// A door's two ends: its `LineString`'s first and last positions (a door is one straight
/// segment; intermediate positions must lie on it, which the wall match then checks).
fn door_ends(f: &serde_json::Value) -> Result<[[f64; 2]; 2], String> {
    let g = f
        .get("geometry")
        .filter(|g| !g.is_null())
        .ok_or("door without a geometry")?;
    let gty = g.get("type").and_then(|t| t.as_str()).unwrap_or("");
    if gty != "LineString" {
        return Err(format!(
            "door geometry type {gty}: a door must be a LineString"
        ));
    }
    let c = coords_array(
        g.get("coordinates")
            .ok_or("LineString without coordinates")?,
    )
    .map_err(|r| format!("door: {r}"))?;
    match (c.first(), c.last()) {
        (Some(a), Some(b)) if c.len() >= 2 => Ok([*a, *b]),
        _ => Err("a door needs two positions".to_string()),
    }
}

fn feature_name(f: &serde_json::Value) -> Option<String> {
    let props = f.get("properties")?;
    ["name", "room", "id"]
        .iter()
        .find_map(|k| match props.get(*k)? {
            serde_json::Value::String(s) if !s.is_empty() => Some(s.clone()),
            serde_json::Value::Number(n) => Some(n.to_string()),
            _ => None,
        })
}

/// A `Feature` (with a Polygon geometry) or a bare `Polygon`.
fn geojson_feature(v: &serde_json::Value) -> Result<RawRoom, String> {
    let ty = v.get("type").and_then(|t| t.as_str()).unwrap_or("");
    let (geometry, name) = match ty {
        "Feature" => (
            v.get("geometry")
                .filter(|g| !g.is_null())
                .ok_or("Feature without a geometry")?,
            feature_name(v),
        ),
        _ => (v, None),
    };
    let gty = geometry.get("type").and_then(|t| t.as_str()).unwrap_or("");
    if gty != "Polygon" {
        return Err(if gty.is_empty() {
            "not a GeoJSON Polygon, Feature or FeatureCollection (no \"type\")".to_string()
        } else {
            format!(
                "geometry type {gty}: a room must be a Polygon{}",
                if gty == "MultiPolygon" {
                    " (split the MultiPolygon into one Polygon feature per room)"
                } else {
                    ""
                }
            )
        });
    }
    let rings = geometry
        .get("coordinates")
        .and_then(|c| c.as_array())
        .ok_or("Polygon without a \"coordinates\" array")?;
    let outer = rings.first().ok_or("Polygon with no ring")?;
    let vertices = coords_array(outer).map_err(|r| format!("outer ring: {r}"))?;
    // Inner rings (holes) are the room's columns.
    let columns = rings[1..]
        .iter()
        .enumerate()
        .map(|(k, ring)| coords_array(ring).map_err(|r| format!("inner ring {k}: {r}")))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(RawRoom {
        name,
        vertices,
        columns,
        warnings: Vec::new(),
    })
}
