//! The number encodings of the payloads (`docs/protocol.md#numbers`): big-endian integers, scaled integers and
//! `f32auto`.
//!
//! Scaled values are decoded to `f64` (`i32 / scale`). Encoding needs a [`Rounding`]: the firmware truncates
//! towards zero after a single-precision product, the PC tools round half away from zero in double precision.

use thiserror::Error;

/// Positions in metres: 0.1 mm resolution.
pub const SCALE_POSITION: f64 = 1e4;
/// Speeds, angles in degrees, IMU values, radii, servo and steering values.
pub const SCALE_FINE: f64 = 1e6;
/// Heights in metres (ENU reference).
pub const SCALE_HEIGHT: f64 = 1e3;
/// Latitude and longitude in degrees.
pub const SCALE_LAT_LON: f64 = 1e16;

/// How a real value becomes a scaled integer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Rounding {
    /// The PC side (control station, bridge): double precision, round half away from zero.
    #[default]
    HalfAwayFromZero,
    /// The firmware: `trunc(f32(f32(x) · f32(s)))`, towards zero in single precision; a value
    /// beyond the integer's range saturates and NaN becomes 0, as the firmware's cast does on its
    /// processor (so a simulated car reports a blown-up estimate instead of falling silent).
    FirmwareTruncate,
}

/// A value that cannot be put on the wire.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum NumberError {
    /// NaN or infinity: undefined in the reference.
    #[error("{field} is not finite ({value})")]
    NotFinite {
        /// The field being encoded.
        field: &'static str,
        /// The offending value.
        value: f64,
    },
    /// The scaled value does not fit the integer (for example a position beyond ±214 748 m).
    #[error("{field} = {value} does not fit the wire integer at scale {scale}")]
    OutOfRange {
        /// The field being encoded.
        field: &'static str,
        /// The offending value.
        value: f64,
        /// The scale that was applied.
        scale: f64,
    },
}

/// Encodes `x` as `i32 = x · scale` (the `f32(s)` encoding).
pub fn scaled_i32(
    field: &'static str,
    x: f64,
    scale: f64,
    rounding: Rounding,
) -> Result<i32, NumberError> {
    if rounding == Rounding::FirmwareTruncate {
        // The firmware's `(int32_t)` cast on its Cortex-M4 (VCVT) saturates and makes NaN 0: a
        // blown-up value (a fault's) is reported clamped, never refused. `as` does exactly that.
        return Ok(((x as f32) * (scale as f32)).trunc() as i32);
    }
    if !x.is_finite() {
        return Err(NumberError::NotFinite { field, value: x });
    }
    let product = (x * scale).round();
    if product < f64::from(i32::MIN) || product > f64::from(i32::MAX) {
        return Err(NumberError::OutOfRange {
            field,
            value: x,
            scale,
        });
    }
    Ok(product as i32)
}

/// Encodes `x` as `i64 = x · scale` (the `f64(s)` encoding). Both roundings compute in double precision.
pub fn scaled_i64(
    field: &'static str,
    x: f64,
    scale: f64,
    rounding: Rounding,
) -> Result<i64, NumberError> {
    if rounding == Rounding::FirmwareTruncate {
        // As for `scaled_i32`: the firmware's conversion saturates and makes NaN 0.
        return Ok((x * scale).trunc() as i64);
    }
    if !x.is_finite() {
        return Err(NumberError::NotFinite { field, value: x });
    }
    let product = (x * scale).round();
    // i64::MAX as f64 rounds up to 2^63, which is itself out of range.
    let limit = 2f64.powi(63);
    if !(-limit..limit).contains(&product) {
        return Err(NumberError::OutOfRange {
            field,
            value: x,
            scale,
        });
    }
    Ok(product as i64)
}

/// Decodes a scaled `i32`.
pub fn unscale_i32(raw: i32, scale: f64) -> f64 {
    f64::from(raw) / scale
}

/// Decodes a scaled `i64`.
pub fn unscale_i64(raw: i64, scale: f64) -> f64 {
    raw as f64 / scale
}

/// Encodes `x` in the reference's `f32auto` form. For normal numbers this is the IEEE-754 binary32 pattern; zero
/// and −0.0 both give `0x00000000`; subnormals get the reference's non-IEEE pattern.
pub fn f32auto_encode(field: &'static str, x: f32) -> Result<u32, NumberError> {
    if !x.is_finite() {
        return Err(NumberError::NotFinite {
            field,
            value: f64::from(x),
        });
    }
    if x == 0.0 {
        return Ok(0);
    }
    let (significand, exponent) = frexp(f64::from(x));
    let sign = if x < 0.0 { 1u32 << 31 } else { 0 };
    let exponent_bits = ((exponent + 126) & 0xFF) as u32;
    let mantissa = ((significand.abs() - 0.5) * 2.0 * f64::from(1u32 << 23)) as u32 & 0x007F_FFFF;
    Ok(sign | (exponent_bits << 23) | mantissa)
}

/// Decodes the `f32auto` form. Exponent and mantissa both 0 is ±0; everything else follows the reference formula
/// `±(mantissa / 2^24 + 0.5) · 2^(exponent − 126)` (an all-ones exponent therefore decodes as ±infinity).
pub fn f32auto_decode(bits: u32) -> f32 {
    let negative = bits & (1 << 31) != 0;
    let exponent = ((bits >> 23) & 0xFF) as i32;
    let mantissa = bits & 0x007F_FFFF;
    let magnitude = if exponent == 0 && mantissa == 0 {
        0.0
    } else {
        (f64::from(mantissa) / f64::from(1u32 << 24) + 0.5) * 2f64.powi(exponent - 126)
    };
    let value = magnitude as f32;
    if negative { -value } else { value }
}

/// Splits a finite non-zero `x` into `sig · 2^e` with `|sig|` in [0.5, 1), like C's `frexp`.
fn frexp(x: f64) -> (f64, i32) {
    let bits = x.to_bits();
    let biased = ((bits >> 52) & 0x7FF) as i32;
    if biased == 0 {
        // Subnormal f64 (never reached from an f32 input, but keep the function total).
        let (sig, e) = frexp(x * 2f64.powi(64));
        return (sig, e - 64);
    }
    let significand = f64::from_bits((bits & !(0x7FF << 52)) | (1022 << 52));
    (significand, biased - 1022)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::approx_constant)] // 2.71828 is the protocol's own example, not e
    fn firmware_truncates_and_pc_rounds() {
        let t = Rounding::FirmwareTruncate;
        let r = Rounding::HalfAwayFromZero;
        assert_eq!(scaled_i32("px", 2.71828, SCALE_POSITION, t), Ok(27182));
        assert_eq!(scaled_i32("px", 2.71828, SCALE_POSITION, r), Ok(27183));
        assert_eq!(scaled_i32("px", -2.71828, SCALE_POSITION, t), Ok(-27182));
        assert_eq!(scaled_i32("px", -2.71828, SCALE_POSITION, r), Ok(-27183));
        assert_eq!(scaled_i32("v", 1.5e-6, SCALE_FINE, t), Ok(1));
        assert_eq!(scaled_i32("v", 1.5e-6, SCALE_FINE, r), Ok(2));
    }

    #[test]
    fn scaled_values_out_of_range_are_errors() {
        let r = Rounding::HalfAwayFromZero;
        assert!(matches!(
            scaled_i32("px", 300_000.0, SCALE_POSITION, r),
            Err(NumberError::OutOfRange { field: "px", .. })
        ));
        assert!(matches!(
            scaled_i32("px", f64::NAN, SCALE_POSITION, r),
            Err(NumberError::NotFinite { .. })
        ));
        assert!(matches!(
            scaled_i64("lat", 1e300, SCALE_LAT_LON, r),
            Err(NumberError::OutOfRange { .. })
        ));
    }

    #[test]
    fn the_firmware_saturates_what_the_host_refuses() {
        let t = Rounding::FirmwareTruncate;
        assert_eq!(
            scaled_i32("px_uwb", 2.6e36, SCALE_POSITION, t),
            Ok(i32::MAX)
        );
        assert_eq!(
            scaled_i32("px_uwb", -2.6e36, SCALE_POSITION, t),
            Ok(i32::MIN)
        );
        assert_eq!(
            scaled_i32("px_uwb", f64::INFINITY, SCALE_POSITION, t),
            Ok(i32::MAX)
        );
        assert_eq!(scaled_i32("px_uwb", f64::NAN, SCALE_POSITION, t), Ok(0));
        assert_eq!(
            scaled_i64("lat", f64::NEG_INFINITY, SCALE_LAT_LON, t),
            Ok(i64::MIN)
        );
        assert_eq!(scaled_i64("lat", f64::NAN, SCALE_LAT_LON, t), Ok(0));
    }

    #[test]
    fn f32auto_vectors() {
        assert_eq!(f32auto_encode("x", 10.0), Ok(0x4120_0000));
        assert_eq!(f32auto_encode("x", -5.5), Ok(0xC0B0_0000));
        assert_eq!(f32auto_encode("x", 2.0), Ok(0x4000_0000));
        assert_eq!(f32auto_encode("x", 0.0), Ok(0));
        assert_eq!(f32auto_encode("x", -0.0), Ok(0));
        assert_eq!(f32auto_decode(0x4120_0000), 10.0);
        assert_eq!(f32auto_decode(0xC0B0_0000), -5.5);
        assert!(f32auto_encode("x", f32::INFINITY).is_err());
    }

    #[test]
    fn f32auto_is_ieee_for_normal_numbers() {
        for x in [
            1.0f32,
            -1.0,
            0.1,
            123.456,
            -7.25e-30,
            3.0e38,
            f32::MIN_POSITIVE,
        ] {
            assert_eq!(f32auto_encode("x", x), Ok(x.to_bits()), "{x}");
            assert_eq!(f32auto_decode(x.to_bits()), x);
        }
    }

    #[test]
    fn f32auto_subnormals_follow_the_reference_not_ieee() {
        let tiny = f32::from_bits(1); // the smallest subnormal, 2^-149
        let bits = f32auto_encode("x", tiny).unwrap_or_default();
        assert_ne!(bits, tiny.to_bits());
        // frexp gives 0.5 · 2^-148, so the exponent field is (-148 + 126) & 0xFF = 234 and the mantissa 0.
        assert_eq!(bits, 234 << 23);
    }
}
