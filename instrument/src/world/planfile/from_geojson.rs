//! The GeoJSON reader of [`super`]: a `Polygon`, a `Feature` with a Polygon geometry, or a
//! `FeatureCollection` of them, one room per feature (outer ring; holes ignored with a
//! warning; longitude / latitude refused).

use super::*;

pub(super) fn geojson_rooms(
    path: &Path,
    value: &serde_json::Value,
) -> Result<Vec<RawRoom>, PlanFileError> {
    let ty = value.get("type").and_then(|t| t.as_str()).unwrap_or("");
    match ty {
        "FeatureCollection" => {
            let features = value
                .get("features")
                .and_then(|f| f.as_array())
                .ok_or_else(|| err(path, None, "FeatureCollection without a \"features\" array"))?;
            if features.is_empty() {
                return Err(err(path, None, "FeatureCollection has no features"));
            }
            features
                .iter()
                .enumerate()
                .map(|(i, f)| {
                    let name = feature_name(f);
                    let label = format!(
                        "feature {i}{}",
                        name.as_ref().map(|n| format!(" '{n}'")).unwrap_or_default()
                    );
                    let mut r =
                        geojson_feature(f).map_err(|reason| err(path, Some(label), reason))?;
                    r.name = Some(name.unwrap_or_else(|| i.to_string()));
                    Ok(r)
                })
                .collect()
        }
        _ => geojson_feature(value)
            .map(|r| vec![r])
            .map_err(|reason| err(path, None, reason)),
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
    let mut warnings = Vec::new();
    if rings.len() > 1 {
        warnings.push(format!(
            "{} hole(s) ignored (columns and other inner walls are not modelled)",
            rings.len() - 1
        ));
    }
    Ok(RawRoom {
        name,
        vertices,
        warnings,
    })
}
