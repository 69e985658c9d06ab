//! The typed scenario: area, routes, anchors, environment, vehicle, generator and campaign settings.
//!
//! Every type here is plain data. A [`Scenario`] built by [`crate::load`] has been validated; one
//! built by hand can be checked with [`Scenario::validate`].

use serde::Deserialize;
use sha2::{Digest, Sha256};
use trajgen::{Area, Constraints, Point, Polygon, Waypoint};

use crate::settings::{CampaignSettings, GeneratorSettings, Vehicle};
use crate::{ScenarioError, Warning};

/// A test area with everything a campaign needs to run in it.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Short name (defaults to the file stem).
    pub name: String,
    /// Free text for people.
    pub description: Option<String>,
    /// Where the local ENU frame's origin is on the globe, when known.
    pub origin: Option<EnuOrigin>,
    /// The drivable region: fence minus cutouts.
    pub area: Area,
    /// The short fixed route every test starts with.
    pub start_route: Route,
    /// The fixed route that leads into the start route.
    pub recovery_route: Route,
    /// The UWB anchors (at most 20, ids unique, 0–255).
    pub anchors: Vec<Anchor>,
    /// What the simulator models around the area (obstacles, reflecting walls).
    pub environment: Environment,
    /// The car's geometry.
    pub vehicle: Vehicle,
    /// The trajectory generator's constants.
    pub generator: GeneratorSettings,
    /// Defaults for campaigns run in this area.
    pub campaign: CampaignSettings,
}

impl Scenario {
    /// The generator's constraints: segment lengths, turn limit (radians) and edge clearance.
    pub fn constraints(&self) -> Constraints {
        self.generator.constraints()
    }

    /// The scenario in canonical TOML (see [`crate::to_toml`]).
    pub fn to_toml(&self) -> String {
        crate::write::to_toml(self)
    }

    /// A content hash: the lowercase hex SHA-256 of the canonical TOML. Two scenarios have the
    /// same hash exactly when they load to the same value; comments and layout do not matter.
    pub fn hash(&self) -> String {
        let digest = Sha256::digest(self.to_toml().as_bytes());
        digest.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// Checks everything [`crate::load`] checks beyond the file's syntax and returns the warnings.
    /// `source_name` names the scenario in errors and warnings.
    pub fn validate(&self, source_name: &str) -> Result<Vec<Warning>, ScenarioError> {
        crate::validate::validate(self, source_name)
    }
}

/// The geodetic position of the local ENU frame's origin.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnuOrigin {
    /// Latitude, degrees (−90..90).
    pub lat: f64,
    /// Longitude, degrees (−180..180).
    pub lon: f64,
    /// Ellipsoidal height, metres.
    pub height: f64,
}

/// A hand-drawn route: the points the car's autopilot follows, in order, each with the speed the
/// car should drive towards it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Route {
    /// The points, in driving order.
    pub points: Vec<Waypoint>,
}

impl Route {
    /// The positions of the points, in order.
    pub fn positions(&self) -> Vec<Point> {
        self.points.iter().map(|p| p.position).collect()
    }

    /// The first point, if any.
    pub fn first(&self) -> Option<&Waypoint> {
        self.points.first()
    }

    /// The last point, if any.
    pub fn last(&self) -> Option<&Waypoint> {
        self.points.last()
    }
}

/// A fixed UWB anchor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anchor {
    /// The anchor's UWB id (the firmware addresses the module by this byte).
    pub id: u8,
    /// East, metres.
    pub x: f64,
    /// North, metres.
    pub y: f64,
    /// Height above ground, metres (the firmware stores it but does not use it).
    pub height: f64,
}

impl Anchor {
    /// The anchor's position in the plane.
    pub fn position(&self) -> Point {
        Point::new(self.x, self.y)
    }
}

/// What the simulator models around the area. May be empty.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Environment {
    /// Objects that block UWB line of sight.
    pub obstacles: Vec<Obstacle>,
    /// Surfaces that reflect UWB signals.
    pub walls: Vec<Wall>,
}

/// An object that blocks UWB line of sight (a rock, a parked car).
#[derive(Debug, Clone, PartialEq)]
pub struct Obstacle {
    /// Name for reports.
    pub name: String,
    /// Its footprint.
    pub polygon: Polygon,
    /// True when it was placed for illustration, not measured.
    pub illustrative: bool,
}

/// A straight reflecting surface, seen from above as a segment.
#[derive(Debug, Clone, PartialEq)]
pub struct Wall {
    /// Name for reports.
    pub name: String,
    /// One end.
    pub a: Point,
    /// The other end.
    pub b: Point,
    /// True when it was placed for illustration, not measured.
    pub illustrative: bool,
}
