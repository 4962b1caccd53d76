//! Parsing and validation of vectors given by users (`--eye 1,2,3`) and files.

use glam::Vec3;

/// Parses `"X,Y,Z"` into a finite vector. The error names the bad component.
pub fn parse_vec3(text: &str) -> Result<Vec3, String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected three comma-separated numbers X,Y,Z, got `{text}`"
        ));
    }
    let mut xyz = [0.0f32; 3];
    for (axis, (part, out)) in ["x", "y", "z"].iter().zip(parts.iter().zip(&mut xyz)) {
        let value: f32 = part
            .parse()
            .map_err(|_| format!("{axis} component `{part}` is not a number"))?;
        if !value.is_finite() {
            return Err(format!("{axis} component is {part}: must be finite"));
        }
        *out = value;
    }
    Ok(Vec3::from_array(xyz))
}

/// Checks that every component of `v` is finite; the error names `what`.
pub fn ensure_finite(what: &str, v: Vec3) -> Result<Vec3, String> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{what} ({}, {}, {}) is not finite", v.x, v.y, v.z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_rejects() {
        assert_eq!(parse_vec3("1, -2,3.5"), Ok(Vec3::new(1.0, -2.0, 3.5)));
        assert!(parse_vec3("1,2").unwrap_err().contains("three"));
        assert!(parse_vec3("1,NaN,2").unwrap_err().contains("y component"));
        assert!(parse_vec3("inf,0,0").unwrap_err().contains("finite"));
        assert!(parse_vec3("1,2,x").unwrap_err().contains("z component `x`"));
        assert!(parse_vec3("1e39,0,0").unwrap_err().contains("finite"));
    }
}
