//! WGS84 longitude and latitude to and from a local east-north-up frame, in metres.
//!
//! Exact on the WGS84 ellipsoid (geodetic → Earth-centred Earth-fixed → ENU, and back with
//! Bowring's iteration), no map projection: the local frame is the plane tangent to the ellipsoid
//! at the origin, the frame every drivecheck scenario is drawn in. Points are taken at the
//! origin's height; over a test area (hundreds of metres) the curvature moves a point by well
//! under a millimetre in the plane.

use crate::model::EnuOrigin;

/// The WGS84 ellipsoid's semi-major axis, metres.
pub const WGS84_A: f64 = 6_378_137.0;
/// The WGS84 ellipsoid's flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;

/// The square of the first eccentricity, `f (2 − f)`.
fn e2() -> f64 {
    WGS84_F * (2.0 - WGS84_F)
}

/// Earth-centred Earth-fixed coordinates, metres, of latitude and longitude (degrees) and
/// ellipsoidal height (metres).
pub fn geodetic_to_ecef(lat: f64, lon: f64, height: f64) -> [f64; 3] {
    let (sin_lat, cos_lat) = lat.to_radians().sin_cos();
    let (sin_lon, cos_lon) = lon.to_radians().sin_cos();
    let n = WGS84_A / (1.0 - e2() * sin_lat * sin_lat).sqrt();
    [
        (n + height) * cos_lat * cos_lon,
        (n + height) * cos_lat * sin_lon,
        (n * (1.0 - e2()) + height) * sin_lat,
    ]
}

/// Latitude and longitude (degrees) and ellipsoidal height (metres) of an ECEF position
/// (Bowring's iteration; converged to well under a micrometre near the ellipsoid's surface).
pub fn ecef_to_geodetic([x, y, z]: [f64; 3]) -> (f64, f64, f64) {
    let p = x.hypot(y);
    let lon = y.atan2(x);
    let mut lat = z.atan2(p * (1.0 - e2()));
    for _ in 0..8 {
        let sin_lat = lat.sin();
        let n = WGS84_A / (1.0 - e2() * sin_lat * sin_lat).sqrt();
        let height = p * lat.cos() + z * sin_lat - WGS84_A * WGS84_A / n;
        lat = z.atan2(p * (1.0 - e2() * n / (n + height)));
    }
    let (sin_lat, cos_lat) = lat.sin_cos();
    let n = WGS84_A / (1.0 - e2() * sin_lat * sin_lat).sqrt();
    let height = p * cos_lat + z * sin_lat - WGS84_A * WGS84_A / n;
    (lat.to_degrees(), lon.to_degrees(), height)
}

/// East, north and up, metres, of a geodetic position in the ENU frame at `origin`.
pub fn geodetic_to_enu(origin: &EnuOrigin, lat: f64, lon: f64, height: f64) -> [f64; 3] {
    let o = geodetic_to_ecef(origin.lat, origin.lon, origin.height);
    let p = geodetic_to_ecef(lat, lon, height);
    let d = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
    let (sin_lat, cos_lat) = origin.lat.to_radians().sin_cos();
    let (sin_lon, cos_lon) = origin.lon.to_radians().sin_cos();
    [
        -sin_lon * d[0] + cos_lon * d[1],
        -sin_lat * cos_lon * d[0] - sin_lat * sin_lon * d[1] + cos_lat * d[2],
        cos_lat * cos_lon * d[0] + cos_lat * sin_lon * d[1] + sin_lat * d[2],
    ]
}

/// Latitude and longitude (degrees) and ellipsoidal height (metres) of a point given in the ENU
/// frame at `origin`.
pub fn enu_to_geodetic(origin: &EnuOrigin, [e, n, u]: [f64; 3]) -> (f64, f64, f64) {
    let o = geodetic_to_ecef(origin.lat, origin.lon, origin.height);
    let (sin_lat, cos_lat) = origin.lat.to_radians().sin_cos();
    let (sin_lon, cos_lon) = origin.lon.to_radians().sin_cos();
    let d = [
        -sin_lon * e - sin_lat * cos_lon * n + cos_lat * cos_lon * u,
        cos_lon * e - sin_lat * sin_lon * n + cos_lat * sin_lon * u,
        cos_lat * n + sin_lat * u,
    ];
    ecef_to_geodetic([o[0] + d[0], o[1] + d[1], o[2] + d[2]])
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn the_equator_at_the_prime_meridian_is_the_semi_major_axis() {
        assert_eq!(geodetic_to_ecef(0.0, 0.0, 0.0), [WGS84_A, 0.0, 0.0]);
        // The pole is at the semi-minor axis b = a (1 − f).
        let pole = geodetic_to_ecef(90.0, 0.0, 0.0);
        assert!(
            (pole[2] - WGS84_A * (1.0 - WGS84_F)).abs() < 1e-6,
            "{pole:?}"
        );
    }

    #[test]
    fn a_step_north_and_east_at_the_equator_is_an_arc_of_the_ellipsoid() {
        let origin = EnuOrigin {
            lat: 0.0,
            lon: 0.0,
            height: 0.0,
        };
        // 1e-5° of longitude on the equator is a · 1e-5 · π/180 m of arc; the chord the ENU
        // plane measures differs by far less than a micrometre.
        let [e, n, _] = geodetic_to_enu(&origin, 0.0, 1e-5, 0.0);
        let arc = WGS84_A * 1e-5_f64.to_radians();
        assert!((e - arc).abs() < 1e-6 && n.abs() < 1e-9, "{e} {n}");
        // North: the meridian's radius of curvature at the equator, a (1 − e²).
        let [e, n, _] = geodetic_to_enu(&origin, 1e-5, 0.0, 0.0);
        let arc = WGS84_A * (1.0 - e2()) * 1e-5_f64.to_radians();
        assert!((n - arc).abs() < 1e-6 && e.abs() < 1e-9, "{e} {n}");
    }

    proptest! {
        #[test]
        fn enu_and_back_is_within_a_micrometre(
            lat in -89.0..89.0f64,
            lon in -180.0..180.0f64,
            height in -100.0..3000.0f64,
            e in -2000.0..2000.0f64,
            n in -2000.0..2000.0f64,
            u in -50.0..50.0f64,
        ) {
            let origin = EnuOrigin { lat, lon, height };
            let (plat, plon, ph) = enu_to_geodetic(&origin, [e, n, u]);
            let back = geodetic_to_enu(&origin, plat, plon, ph);
            for (a, b) in back.iter().zip([e, n, u]) {
                prop_assert!((a - b).abs() < 1e-6, "{back:?} vs {:?}", [e, n, u]);
            }
        }
    }
}
