//! Parsing and validation of vectors given by users (`--eye 1,2,3`) and files.

use glam::{DVec3, Vec3};

/// A vector that is not three finite numbers; the message names what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VectorError {
    #[error("expected three comma-separated numbers X,Y,Z, got `{0}`")]
    NotThree(String),
    #[error("{axis} component `{part}` is not a number")]
    NotANumber { axis: &'static str, part: String },
    #[error("{axis} component is {part}: must be finite")]
    NotFiniteComponent { axis: &'static str, part: String },
    /// `what` (the vector's name) holds NaN or infinity.
    #[error("{what} ({}, {}, {}) is not finite", value.x, value.y, value.z)]
    NotFinite { what: String, value: DVec3 },
}

/// Parses `"X,Y,Z"` into a finite vector. The error names the bad component.
pub fn parse_vec3(text: &str) -> Result<Vec3, VectorError> {
    let v = parse_dvec3(text)?;
    // (A component finite in f64 but past f32's range is named as not finite.)
    for (axis, (x, part)) in ["x", "y", "z"]
        .into_iter()
        .zip(v.to_array().into_iter().zip(text.split(',')))
    {
        if !(x as f32).is_finite() {
            return Err(VectorError::NotFiniteComponent {
                axis,
                part: part.trim().to_string(),
            });
        }
    }
    Ok(v.as_vec3())
}

/// Parses `"X,Y,Z"` into a finite vector of `f64`s: a position, which may lie far
/// from the origin. The error names the bad component.
pub fn parse_dvec3(text: &str) -> Result<DVec3, VectorError> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(VectorError::NotThree(text.to_string()));
    }
    let mut xyz = [0.0f64; 3];
    for (axis, (part, out)) in ["x", "y", "z"].into_iter().zip(parts.iter().zip(&mut xyz)) {
        let value: f64 = part.parse().map_err(|_| VectorError::NotANumber {
            axis,
            part: part.to_string(),
        })?;
        if !value.is_finite() {
            return Err(VectorError::NotFiniteComponent {
                axis,
                part: part.to_string(),
            });
        }
        *out = value;
    }
    Ok(DVec3::from_array(xyz))
}

/// Checks that every component of `v` is finite; the error names `what`.
pub fn ensure_finite(what: &str, v: Vec3) -> Result<Vec3, VectorError> {
    ensure_finite_f64(what, v.as_dvec3()).map(|_| v)
}

/// As [`ensure_finite`], for a vector of `f64`s.
pub fn ensure_finite_f64(what: &str, v: DVec3) -> Result<DVec3, VectorError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(VectorError::NotFinite {
            what: what.to_string(),
            value: v,
        })
    }
}

/// The unit vector along `v`, or `None` for a zero or non-finite one. A finite vector
/// whose squared length over- or underflows (components beyond about 1.8e19, or tiny
/// ones) is scaled by its largest component first, so it still normalises; any other
/// is normalised as it is (the same bits as `normalize`).
pub fn direction(v: Vec3) -> Option<Vec3> {
    if v.length_squared().is_normal() {
        return Some(v.normalize());
    }
    let largest = v.abs().max_element();
    (largest > 0.0 && largest.is_finite()).then(|| (v / largest).normalize())
}

/// The unit vector along `v` (rounded to `f32`), or `None` for a zero or non-finite
/// one; as [`direction`], scaled first when its squared length would over- or
/// underflow.
pub fn direction_f64(v: DVec3) -> Option<Vec3> {
    if v.length_squared().is_normal() {
        return Some(v.normalize().as_vec3());
    }
    let largest = v.abs().max_element();
    (largest > 0.0 && largest.is_finite()).then(|| (v / largest).normalize().as_vec3())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_rejects() {
        assert_eq!(parse_vec3("1, -2,3.5"), Ok(Vec3::new(1.0, -2.0, 3.5)));
        assert!(parse_vec3("1,2").unwrap_err().to_string().contains("three"));
        assert!(
            parse_vec3("1,NaN,2")
                .unwrap_err()
                .to_string()
                .contains("y component")
        );
        assert!(parse_vec3("inf,0,0").unwrap_err().to_string().contains("finite"));
        assert!(
            parse_vec3("1,2,x")
                .unwrap_err()
                .to_string()
                .contains("z component `x`")
        );
        assert!(parse_vec3("1e39,0,0").unwrap_err().to_string().contains("finite"));
    }

    #[test]
    fn directions_of_huge_tiny_zero_and_infinite_vectors() {
        let unit = Vec3::new(1.0, -2.0, 2.0) / 3.0;
        for scale in [1.0, 1e20, 1e-30, 3e38] {
            let d = direction(unit * scale).expect("a direction");
            assert!(d.abs_diff_eq(unit, 1e-6), "{scale}: {d}");
        }
        // Ordinary vectors: exactly `normalize`.
        assert_eq!(
            direction(Vec3::new(3.0, 4.0, 0.5)),
            Some(Vec3::new(3.0, 4.0, 0.5).normalize())
        );
        assert_eq!(direction(Vec3::ZERO), None);
        assert_eq!(direction(Vec3::new(f32::INFINITY, 0.0, 0.0)), None);
        assert_eq!(direction(Vec3::NAN), None);
    }
}
