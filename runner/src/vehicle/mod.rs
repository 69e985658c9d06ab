//! The vehicle seam: what the runner and the commands drive, and nothing more.
//!
//! [`Vehicle`] is every operation the runner performs on a car: the firmware's identity, the
//! link's timing and health, state reads (one at a time and the pipelined stream the telemetry
//! polls), the route (cleared, extended, the autopilot switched), braking, the UWB pose, the
//! anchors, the configuration preflight reads and writes, and fault injection (enable, add, list,
//! clear, reset the UWB estimate). `runner/` and `commands/` are written against it and never
//! name a concrete car; [`connect`] is the one place that builds one from what the user named.
//!
//! The seam speaks `car-link`'s vocabulary: states are [`StateSample`]s, routes
//! [`RoutePoint`]s, health a [`LinkHealth`], and failures [`CarError`]s, since the runner's
//! decisions hang on their distinctions (a lost link, [`CarError::LinkLost`], aborts the test and
//! is never retried; a fault command whose reply was lost, `CarError::Fault(FaultError::NoReply)`,
//! is resolved by listing the car's faults). Another firmware family or a bridge maps what it
//! speaks onto these.
//!
//! Implemented here for [`car_link::Car`], the client of the RISE firmware family (every method
//! is the client's own: see its docs for each one's timeout and cancellation). The trait has
//! `Send` futures and asks `Clone + Send + Sync + 'static`, because the telemetry polls on a task
//! of its own with a clone of the car, and an operation in flight is a boxed future beside it.
//!
//! Why the trait lives here and not in `car-link`: it is the runner's contract (what the method
//! needs of a car, e.g. a partial fault list for a lossy link, the configured tries preflight
//! scales), and `car-link` is one family's protocol; a connection for another family is a module
//! beside [`connect`] that implements it.

mod connect;
pub mod sitl;

use std::future::Future;
use std::pin::Pin;
use std::time::Duration;

use car_link::config::{ConfigField, MainConfig};
use car_link::fault::ListedFault;
use car_link::health::LinkHealth;
use car_link::message::{Anchor, Pose};
use car_link::{
    Car, CarError, FaultKind, FirmwareVersion, Probe, RoutePoint, StatePolling, StateSample,
};
use car_sim::{DebugEvent, Truth};
use futures::Stream;
use trajgen::Point;

#[cfg(test)]
pub(crate) use connect::over_stream;
pub use connect::{ConnectError, EmbeddedSims, connect, connect_fresh, connect_sim, placed};

/// A car the runner drives (see the module doc). Every async method is bounded by the link's
/// timeouts; a lost link is [`CarError::LinkLost`], never a default value.
pub trait Vehicle: Clone + Send + Sync + 'static {
    // Identity and link.

    /// The firmware version the car reported (its profile says what it is like).
    fn version(&self) -> FirmwareVersion;

    /// The per-try timeout of requests in force.
    fn request_timeout(&self) -> Duration;

    /// Sets the per-try timeout of every request from now on (preflight sets what the measured
    /// round trip needs).
    fn set_request_timeout(&self, per_try: Duration);

    /// The tries of an acked request the connection was configured with (not the ones in force).
    fn configured_tries(&self) -> u32;

    /// Sets how many times every acked request from now on is tried.
    fn set_tries(&self, tries: u32);

    /// The link's health: round trips, timeouts, reconnects.
    fn health(&self) -> LinkHealth;

    /// Switches the watchdog keepalive on or off (off while preflight measures the round trip).
    fn set_keepalive(&self, on: bool);

    // State.

    /// One state read, tried once with the per-try timeout in force.
    fn state(&self) -> impl Future<Output = Result<StateSample, CarError>> + Send;

    /// One state read that waits up to `per_try` for its reply.
    fn state_within(
        &self,
        per_try: Duration,
    ) -> impl Future<Output = Result<StateSample, CarError>> + Send;

    /// States polled as `polling` says, pipelined; failures are items, and the stream never ends.
    fn poll_states(
        &self,
        polling: StatePolling,
    ) -> impl Stream<Item = Result<StateSample, CarError>> + Send + 'static;

    // Route and motion.

    /// Empties the route and deactivates the autopilot (it does not brake).
    fn clear_route(&self) -> impl Future<Output = Result<(), CarError>> + Send;

    /// Appends `points` to the route, confirmed.
    fn add_points(
        &self,
        points: &[RoutePoint],
    ) -> impl Future<Output = Result<(), CarError>> + Send;

    /// Reads `num` (at most 20) points of the route back from point `first`, with the route's
    /// length.
    fn route_part(
        &self,
        first: i32,
        num: u8,
    ) -> impl Future<Output = Result<car_link::message::RoutePart, CarError>> + Send;

    /// Activates or deactivates the autopilot; `reset` restarts the route from its first point.
    fn set_autopilot(
        &self,
        active: bool,
        reset: bool,
    ) -> impl Future<Output = Result<(), CarError>> + Send;

    /// Brakes with `current_a` amperes (and deactivates the autopilot); success means sent.
    fn brake(&self, current_a: f64) -> impl Future<Output = Result<(), CarError>> + Send;

    /// Sets the fused and UWB pose.
    fn set_pos(&self, pose: Pose) -> impl Future<Output = Result<(), CarError>> + Send;

    // Setup.

    /// Replaces the car's UWB anchors.
    fn upload_anchors(
        &self,
        anchors: &[Anchor],
    ) -> impl Future<Output = Result<(), CarError>> + Send;

    /// Reads the main configuration.
    fn main_config(&self) -> impl Future<Output = Result<MainConfig, CarError>> + Send;

    /// Switches off what the method cannot drive with (repeated routes, time mode, the UWB
    /// position reported in place of the fused one); the fields changed, with their old values.
    fn prepare_for_test_drive(
        &self,
    ) -> impl Future<Output = Result<Vec<(ConfigField, u8)>, CarError>> + Send;

    // Fault injection.

    /// Switches fault injection on or off.
    fn set_fi_enabled(&self, enabled: bool) -> impl Future<Output = Result<(), CarError>> + Send;

    /// Adds a fault on `probe` (`start` in probe iterations from now, `duration` 0: permanent).
    fn add_fault(
        &self,
        probe: &Probe,
        kind: FaultKind,
        param: f32,
        start: i32,
        duration: i32,
    ) -> impl Future<Output = Result<(), CarError>> + Send;

    /// The faults of whatever part of the car's fault list arrived (on a lossy link several
    /// reads show every fault between them).
    fn list_faults_part(&self) -> impl Future<Output = Result<Vec<ListedFault>, CarError>> + Send;

    /// Frees every fault slot.
    fn clear_faults(&self) -> impl Future<Output = Result<(), CarError>> + Send;

    /// Resets the UWB position to the fused one.
    fn reset_uwb_pos(&self) -> impl Future<Output = Result<(), CarError>> + Send;
}

/// The RISE firmware family over `car-link`'s client: each method is the client's own.
impl Vehicle for Car {
    fn version(&self) -> FirmwareVersion {
        Car::version(self)
    }

    fn request_timeout(&self) -> Duration {
        Car::request_timeout(self)
    }

    fn set_request_timeout(&self, per_try: Duration) {
        Car::set_request_timeout(self, per_try);
    }

    fn configured_tries(&self) -> u32 {
        self.config().tries
    }

    fn set_tries(&self, tries: u32) {
        Car::set_tries(self, tries);
    }

    fn health(&self) -> LinkHealth {
        Car::health(self)
    }

    fn set_keepalive(&self, on: bool) {
        Car::set_keepalive(self, on);
    }

    fn state(&self) -> impl Future<Output = Result<StateSample, CarError>> + Send {
        Car::state(self)
    }

    fn state_within(
        &self,
        per_try: Duration,
    ) -> impl Future<Output = Result<StateSample, CarError>> + Send {
        Car::state_within(self, per_try)
    }

    fn poll_states(
        &self,
        polling: StatePolling,
    ) -> impl Stream<Item = Result<StateSample, CarError>> + Send + 'static {
        Car::poll_states(self, polling)
    }

    fn clear_route(&self) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::clear_route(self)
    }

    fn add_points(
        &self,
        points: &[RoutePoint],
    ) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::add_points(self, points)
    }

    fn route_part(
        &self,
        first: i32,
        num: u8,
    ) -> impl Future<Output = Result<car_link::message::RoutePart, CarError>> + Send {
        Car::route_part(self, first, num)
    }

    fn set_autopilot(
        &self,
        active: bool,
        reset: bool,
    ) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::set_autopilot(self, active, reset)
    }

    fn brake(&self, current_a: f64) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::brake(self, current_a)
    }

    fn set_pos(&self, pose: Pose) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::set_pos(self, pose)
    }

    fn upload_anchors(
        &self,
        anchors: &[Anchor],
    ) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::upload_anchors(self, anchors)
    }

    fn main_config(&self) -> impl Future<Output = Result<MainConfig, CarError>> + Send {
        Car::main_config(self)
    }

    fn prepare_for_test_drive(
        &self,
    ) -> impl Future<Output = Result<Vec<(ConfigField, u8)>, CarError>> + Send {
        Car::prepare_for_test_drive(self)
    }

    fn set_fi_enabled(&self, enabled: bool) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::set_fi_enabled(self, enabled)
    }

    fn add_fault(
        &self,
        probe: &Probe,
        kind: FaultKind,
        param: f32,
        start: i32,
        duration: i32,
    ) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::add_fault(self, probe, kind, param, start, duration)
    }

    fn list_faults_part(&self) -> impl Future<Output = Result<Vec<ListedFault>, CarError>> + Send {
        Car::list_faults_part(self)
    }

    fn clear_faults(&self) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::clear_faults(self)
    }

    fn reset_uwb_pos(&self) -> impl Future<Output = Result<(), CarError>> + Send {
        Car::reset_uwb_pos(self)
    }
}

/// Where a fresh simulated car stands when its test begins.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartPose {
    /// Its position.
    pub position: Point,
    /// Its heading, radians counter-clockwise from east.
    pub heading: f64,
}

/// A connected car and its simulator's debug view.
pub type FreshCar<V> = (V, Box<dyn SimulatorView>);

/// What [`FreshCars::connect`] returns.
pub type Connecting<'a, V> = Pin<Box<dyn Future<Output = Result<FreshCar<V>, ConnectError>> + 'a>>;

/// Makes the simulated car of each test ([`EmbeddedSims`] makes them with `car-sim`).
pub trait FreshCars: Sync {
    /// The cars it makes.
    type Vehicle: Vehicle;

    /// Whether the cars run in virtual time: each test's runtime then has a paused clock.
    fn virtual_time(&self) -> bool;

    /// A fresh simulated car for test `test_index`, standing at `start` (`None`: at the start
    /// of the scenario's start route), connected. Called inside the test's runtime.
    fn connect(&self, test_index: usize, start: Option<StartPose>)
    -> Connecting<'_, Self::Vehicle>;
}

/// The embedded simulator's debug view, recorded beside every state sample of a simulated run.
pub trait SimulatorView: Sync {
    /// The simulator's hidden truth now.
    fn truth(&self) -> Truth;
    /// The debug events since the last call.
    fn take_events(&self) -> Vec<DebugEvent>;
}
