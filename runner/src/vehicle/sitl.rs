//! The car's own firmware, built for the host (`sitl`), as a car: the executable runs in
//! lockstep with tokio's clock, its car-protocol bytes go both ways through an in-process pipe to
//! `car-link`'s client (so the runner drives it as it drives any car), and a [`Plant`] — the
//! physical car and its world, `car-sim`'s physics without `car-sim`'s firmware model — answers
//! its motor and servo commands, feeds its IMU, its motor controller's values, its GNSS receiver's
//! NMEA and its UWB module's ranges.
//!
//! The bridge (`docs/sitl.md#in-a-campaign`): every [`STEP`] of tokio time the firmware is
//! advanced by the same; the plant ticks every 10 ms (the simulated car's tick); bytes from the
//! client reach the firmware at the next advance, the firmware's replies reach the client at the
//! end of the advance that produced them. On a paused clock that is virtual time: the campaign is
//! as deterministic as the firmware is (the same inputs give it the same outputs, byte for byte).
//!
//! Before the client speaks, the bridge does what a car's operator does once: lets the firmware
//! start up standing still, gives it the ENU reference of the test area ([`ORIGIN`]) and its
//! pose where the plant stands (SET_ENU_REF, SET_POS). Its GNSS fixes then keep the fused
//! position on the truth, as RTK does on the car.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use car_link::frame::{FrameDecoder, FrameEncoder};
use car_link::message::{Dialect, EnuRef, Pose};
use car_link::{Car, CarError, FirmwareVersion, Reply, Request};
use car_sim::motor::MotorCommand as PlantMotor;
use car_sim::plant::{GeodeticOrigin, GnssMeasurement, Plant, PlantOptions};
use car_sim::{DebugEvent, FwPose, Placement, RangeResult, Truth};
use sitl::protocol::{Imu, MotorCommand, MotorValues, SitlFrame};
use sitl::{SitlError, SitlProcess};
use thiserror::Error;
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::connect::car_config;
use super::{Connecting, FreshCars, SimulatorView, StartPose};
use campaign::seed::Purpose;

/// How often the firmware is advanced (and the longest a byte waits to reach it).
pub const STEP: Duration = Duration::from_millis(5);
/// The plant's tick.
const PLANT_TICK_US: u64 = 10_000;
/// How long the firmware runs standing still before the client speaks: past 10.x's 1 s gyro
/// calibration in `pos_init`.
const START_UP: Duration = Duration::from_millis(1_500);
/// The delay between a range request and its answer (the exchanges take a few ms; the
/// simulated car's figure).
const RANGE_REPLY_US: u64 = 10_000;
/// The IMU's white noise (g, °/s): a perfectly constant IMU makes the firmware's Madgwick filter
/// divide by zero (`docs/sitl.md#traps`).
const IMU_NOISE: (f32, f32) = (0.002, 0.05);
/// The geodetic place of the local frame's origin: the test areas are local metres, and the
/// firmware needs a reference to turn its receiver's fixes into them (any place works; this is
/// Borås, where the firmware was written).
pub const ORIGIN: GeodeticOrigin = GeodeticOrigin {
    lat: 57.7210,
    lon: 12.9401,
    height: 150.0,
};
/// UTC time of day when the executable starts, ms (the simulated car's default).
const UTC_AT_START_MS: u64 = 12 * 3_600_000;

/// Why a firmware car could not be started.
#[derive(Debug, Error)]
pub enum SitlCarError {
    /// The executable did not start or its link failed during the start-up.
    #[error("the firmware built for the host ({executable}) did not start")]
    Start {
        /// The executable.
        executable: PathBuf,
        /// Why.
        #[source]
        source: SitlError,
    },
    /// The firmware is a version `car-link` does not speak.
    #[error("the firmware built for the host is {0}.{1}, which drivecheck does not speak")]
    Version(u8, u8),
    /// The client could not connect over the pipe.
    #[error("cannot connect to the firmware built for the host")]
    Connect(#[source] CarError),
    /// The firmware did not answer GET_MAIN_CONFIG after its start-up.
    #[error("the firmware built for the host did not report its main configuration")]
    Config(#[source] CarError),
    /// No runtime for the start that reads the configuration.
    #[error("cannot start the async runtime")]
    Runtime(#[source] std::io::Error),
}

/// The car's own firmware built for the host: its executable and the version it reports.
#[derive(Debug, Clone, PartialEq)]
pub struct HostFirmware {
    /// The executable (`sitl::Build::executable`).
    pub executable: PathBuf,
    /// Its firmware version.
    pub version: FirmwareVersion,
    /// SHA-256 (hex) of the tree's files that went into it (`sitl::Build::tree_hash`): which
    /// firmware a campaign drove, recorded in `campaign.json`.
    pub tree_hash: String,
    /// The configuration it boots with ([`boot_config`]): the tree's own `conf_general.c`
    /// defaults, whose geometry (gearing, wheel, wheelbase, steering, GNSS antenna) its
    /// physical car is given.
    pub config: car_sim::FirmwareConfig,
}

/// The geometry fields of `config` that differ from `version`'s defaults, as `name value
/// (default)`, if any.
pub fn geometry_differences(
    config: &car_sim::FirmwareConfig,
    version: FirmwareVersion,
) -> Option<String> {
    let defaults = car_sim::FirmwareConfig::defaults(version);
    let (v, d) = (&config.vehicle, &defaults.vehicle);
    let differs: Vec<String> = [
        ("gear_ratio", v.gear_ratio, d.gear_ratio),
        ("wheel_diam", v.wheel_diam, d.wheel_diam),
        ("motor_poles", v.motor_poles, d.motor_poles),
        ("axis_distance", v.axis_distance, d.axis_distance),
        (
            "steering_max_angle_rad",
            v.steering_max_angle_rad,
            d.steering_max_angle_rad,
        ),
        ("steering_center", v.steering_center, d.steering_center),
        ("steering_range", v.steering_range, d.steering_range),
        ("gps_ant_x", config.gps_ant_x, defaults.gps_ant_x),
        ("gps_ant_y", config.gps_ant_y, defaults.gps_ant_y),
    ]
    .into_iter()
    .filter(|(_, value, default)| value != default)
    .map(|(name, value, default)| format!("{name} {value} ({default})"))
    .collect();
    (!differs.is_empty()).then(|| differs.join(", "))
}

/// The main configuration `executable` (firmware `version`) boots with: a fresh start of it in
/// virtual time, standing in an empty world, asked GET_MAIN_CONFIG once its start-up is over. A
/// tree whose `conf_general.c` defaults differ from its generation's (another car's wheel or
/// wheelbase) reports its own here.
pub fn boot_config(
    executable: &Path,
    version: FirmwareVersion,
) -> Result<car_sim::FirmwareConfig, SitlCarError> {
    let car = SitlCar {
        executable: executable.to_path_buf(),
        plant: plant_of(
            &car_sim::FirmwareConfig::defaults(version),
            &car_sim::SimConfig::default(),
        ),
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .start_paused(true)
        .build()
        .map_err(SitlCarError::Runtime)?;
    runtime.block_on(async {
        let (client, _handle) = connect_sitl(&car).await?;
        let record = client.main_config().await.map_err(SitlCarError::Config)?;
        Ok(car_sim::protocol::firmware_config_from(&record, version))
    })
}

/// The firmware executable of a build, and the physical car it drives.
#[derive(Debug, Clone)]
pub struct SitlCar {
    /// The executable (`sitl::Build::executable`).
    pub executable: PathBuf,
    /// The physical car, its world and its noise streams' seed.
    pub plant: PlantOptions,
}

/// What the bridge shares with its handle.
#[derive(Debug)]
struct Shared {
    truth: Truth,
    events: Vec<DebugEvent>,
    /// Why the bridge stopped, when it stopped on an error.
    ended: Option<String>,
}

/// A running firmware car. Dropping it stops the bridge and the executable.
#[derive(Debug)]
pub struct SitlHandle {
    shared: Arc<Mutex<Shared>>,
    task: JoinHandle<()>,
}

impl SitlHandle {
    fn lock(&self) -> std::sync::MutexGuard<'_, Shared> {
        self.shared.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Why the bridge stopped, when the firmware or its link failed (the client then sees a lost
    /// link).
    pub fn ended(&self) -> Option<String> {
        self.lock().ended.clone()
    }
}

impl Drop for SitlHandle {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl SimulatorView for SitlHandle {
    fn truth(&self) -> Truth {
        self.lock().truth
    }

    fn take_events(&self) -> Vec<DebugEvent> {
        std::mem::take(&mut self.lock().events)
    }
}

/// Starts the firmware of `car` standing where its plant stands, runs its start-up, and
/// connects `car-link`'s client to it. Must be called inside a tokio runtime (on a paused clock
/// it runs in virtual time).
///
/// Timeout: the start-up is [`START_UP`] of the firmware's time; then the client's connection
/// handshake.
pub async fn connect_sitl(car: &SitlCar) -> Result<(Car, SitlHandle), SitlCarError> {
    let (stream, handle) = start_sitl(car)?;
    let client = Car::over_stream(stream, car_config())
        .await
        .map_err(SitlCarError::Connect)?;
    Ok((client, handle))
}

/// Starts the firmware of `car` as [`connect_sitl`] does and gives the host's end of its car
/// link: the bytes a car's USB link would carry, both ways. Must be called inside a tokio
/// runtime; the bridge runs on its clock (real time on a clock that is not paused).
pub fn start_sitl(car: &SitlCar) -> Result<(DuplexStream, SitlHandle), SitlCarError> {
    let start = |source| SitlCarError::Start {
        executable: car.executable.clone(),
        source,
    };
    let process = SitlProcess::start(&car.executable).map_err(start)?;
    let (major, minor) = process.firmware_version();
    let version = FirmwareVersion::new(major, minor);
    if !version.profile().supported {
        return Err(SitlCarError::Version(major, minor));
    }
    let plant = Plant::new(car.plant.clone());
    let mut bridge = Bridge::new(process, plant, version);
    bridge.start_up().map_err(start)?;
    let shared = Arc::new(Mutex::new(Shared {
        truth: bridge.truth(),
        events: Vec::new(),
        ended: None,
    }));
    let pipe = car_link::transport::sim_pipe();
    let task = tokio::spawn(bridge.run(pipe.car, shared.clone()));
    Ok((pipe.host, SitlHandle { shared, task }))
}

/// Serves the firmware of `car` over TCP on `listener`, one client at a time, as a car's
/// TCP bridge serves its USB link (`drivecheck sim --car sitl:TREE`): one firmware for every
/// connection, running on tokio's clock (in real time), standing still between clients. Returns
/// when the firmware stops (its reason), or never.
pub async fn serve_sitl_tcp(
    car: &SitlCar,
    listener: tokio::net::TcpListener,
) -> Result<String, SitlCarError> {
    let (link, handle) = start_sitl(car)?;
    let (mut from_car, mut to_car) = tokio::io::split(link);
    loop {
        let (socket, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(accepted) => accepted,
                Err(e) => {
                    tracing::warn!("cannot accept a connection: {e}");
                    continue;
                }
            },
            () = ended(&handle) => break,
        };
        tracing::info!("a client connected from {peer}");
        let _ = socket.set_nodelay(true);
        let (mut socket_in, mut socket_out) = socket.into_split();
        // Until the client goes (or the firmware stops); the link itself stays open for the
        // next client, so neither copy shuts down what it writes to.
        tokio::select! {
            _ = tokio::io::copy(&mut socket_in, &mut to_car) => {}
            _ = tokio::io::copy(&mut from_car, &mut socket_out) => {}
            () = ended(&handle) => break,
        }
        tracing::info!("the client from {peer} left");
    }
    Ok(handle
        .ended()
        .unwrap_or_else(|| "the firmware's link closed".to_owned()))
}

/// Resolves once the bridge of `handle` stopped.
async fn ended(handle: &SitlHandle) {
    while handle.ended().is_none() && !handle.task.is_finished() {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// The firmware, the plant, and what is on its way between them.
struct Bridge {
    process: SitlProcess,
    plant: Plant,
    version: FirmwareVersion,
    /// Range answers due, in order: (due µs of firmware time, module id, anchor, metres).
    ranges: VecDeque<(u64, u8, u8, f32)>,
    /// Fixes measured and not yet arrived.
    fixes: VecDeque<GnssMeasurement>,
    /// The firmware time at which the plant is at time 0.
    plant_zero_us: u64,
    /// The plant time of the receiver's next pulse per second, ms (every whole UTC second).
    next_pps_ms: u64,
    /// The last fused and UWB poses the firmware reported (GET_STATE replies on their way to
    /// the client): the truth's estimates.
    fused: FwPose,
    uwb: FwPose,
    decoder: FrameDecoder,
    events: Vec<DebugEvent>,
}

impl Bridge {
    fn new(process: SitlProcess, plant: Plant, version: FirmwareVersion) -> Self {
        let p = plant.options().placement;
        let pose = FwPose {
            x: p.x as f32,
            y: p.y as f32,
            yaw: (-p.heading.to_degrees()) as f32,
        };
        Self {
            plant_zero_us: process.now_us(),
            next_pps_ms: 1000 - UTC_AT_START_MS % 1000,
            process,
            plant,
            version,
            ranges: VecDeque::new(),
            fixes: VecDeque::new(),
            fused: pose,
            uwb: pose,
            decoder: FrameDecoder::host(),
            events: Vec::new(),
        }
    }

    /// Standing still through the firmware's start-up, then the ENU reference and the pose.
    fn start_up(&mut self) -> Result<(), SitlError> {
        self.feed_sensors()?;
        let seed = self.plant.options().seed;
        self.process.set_imu_noise(IMU_NOISE.0, IMU_NOISE.1, seed)?;
        let steps = START_UP.as_micros() as u64 / PLANT_TICK_US;
        for _ in 0..steps {
            self.tick()?;
        }
        let p = self.plant.options().placement;
        for request in [
            Request::SetEnuRef(EnuRef {
                lat: ORIGIN.lat,
                lon: ORIGIN.lon,
                height: ORIGIN.height,
            }),
            Request::SetPos(Pose {
                x: p.x,
                y: p.y,
                yaw: -p.heading.to_degrees(),
            }),
        ] {
            self.request(&request)?;
            self.tick()?;
        }
        // settle: a few fixes in the new frame
        for _ in 0..50 {
            self.tick()?;
        }
        self.decoder = FrameDecoder::host();
        self.events.clear();
        Ok(())
    }

    /// A request of the bridge's own (its reply is not the client's and is dropped).
    fn request(&mut self, request: &Request) -> Result<(), SitlError> {
        let payload = request
            .encode(car_link::message::ID_ALL, Dialect::host(self.version))
            .map_err(|e| SitlError::Firmware(format!("cannot encode {request:?}: {e}")))?;
        let frame = FrameEncoder::to_firmware()
            .encode_to_bytes(&payload)
            .map_err(|e| SitlError::Firmware(format!("cannot frame {request:?}: {e}")))?;
        self.process.send_car_bytes(&frame)
    }

    /// The plant's time in the firmware's.
    fn plant_us(&self) -> u64 {
        self.plant_zero_us + self.plant.now_ms() * 1000
    }

    fn feed_sensors(&mut self) -> Result<(), SitlError> {
        let imu = self.plant.imu();
        self.process.set_imu(Imu {
            accel: imu.accel_g.map(|a| a as f32),
            gyro: imu.gyro_dps.map(|g| g as f32),
            mag: imu.mag.map(|m| m as f32),
        })?;
        let m = self.plant.motor_reading();
        self.process.set_motor_values(MotorValues {
            rpm: m.rpm as f32,
            tachometer: m.tachometer,
            tachometer_abs: m.tachometer_abs,
            v_in: m.v_in as f32,
            current_motor: 0.0,
            duty_now: m.duty as f32,
        })
    }

    /// One plant tick and the firmware advanced to it; the firmware's car bytes are returned.
    fn tick(&mut self) -> Result<Vec<u8>, SitlError> {
        self.plant.step();
        if let Some(fix) = self.plant.gnss_fix() {
            self.fixes.push_back(fix);
        }
        self.feed_sensors()?;
        let target = self.plant_us();
        let mut out = Vec::new();
        // advance in STEPs within the tick so that range answers and fixes land on time
        let mut t = self.process.now_us();
        while t < target {
            t = (t + STEP.as_micros() as u64).min(target);
            out.extend(self.advance_to(t)?);
        }
        Ok(out)
    }

    /// Delivers what is due by `t_us`, advances the firmware there and handles its outputs.
    fn advance_to(&mut self, t_us: u64) -> Result<Vec<u8>, SitlError> {
        // The pulse first: the fix of that second arrives after it, with the receiver's latency.
        if self.plant_zero_us + self.next_pps_ms * 1000 <= t_us {
            self.process.pps()?;
            self.next_pps_ms += 1000;
        }
        while let Some(fix) = self.fixes.front().copied() {
            if self.plant_zero_us + fix.arrives_ms * 1000 > t_us {
                break;
            }
            self.fixes.pop_front();
            let sentence = ORIGIN.gga(fix.x, fix.y, UTC_AT_START_MS + fix.measured_ms);
            self.process.send_nmea(&sentence)?;
        }
        while let Some(&(due, id, dest, range)) = self.ranges.front() {
            if due > t_us {
                break;
            }
            self.ranges.pop_front();
            self.process.send_uwb_range(id, dest, range)?;
        }
        let frames = self.process.advance_to(t_us)?;
        let mut bytes = Vec::new();
        for frame in frames {
            match frame {
                SitlFrame::CarBytes { bytes: b, .. } => {
                    self.snoop(&b);
                    bytes.extend(b);
                }
                SitlFrame::Motor { command, .. } => self.plant.command_motor(match command {
                    MotorCommand::Duty(d) => PlantMotor::Duty(d),
                    MotorCommand::Current(a) => PlantMotor::Current(a),
                    MotorCommand::CurrentBrake(a) | MotorCommand::Handbrake(a) => {
                        PlantMotor::CurrentBrake(a)
                    }
                    MotorCommand::Rpm(r) => PlantMotor::Rpm(r),
                    MotorCommand::Pos(_) => PlantMotor::Position,
                }),
                SitlFrame::Servo { pos, .. } => self.plant.command_servo(pos),
                SitlFrame::UwbRequest { t_us, id, dest, .. } => {
                    let m = self.plant.range(dest);
                    self.events.push(DebugEvent::Range {
                        at_ms: self.plant.now_ms(),
                        anchor: dest,
                        path: m.path,
                        true_range: m.true_range,
                        result: m.result,
                    });
                    if let RangeResult::Measured(r) = m.result {
                        self.ranges.push_back((t_us + RANGE_REPLY_US, id, dest, r));
                    }
                }
                SitlFrame::Note { .. }
                | SitlFrame::Hello { .. }
                | SitlFrame::Advanced(_)
                | SitlFrame::Stats { .. } => {}
                SitlFrame::Error(text) => return Err(SitlError::Firmware(text)),
            }
        }
        Ok(bytes)
    }

    /// Reads the firmware's state replies on their way to the client: the truth's estimates.
    fn snoop(&mut self, bytes: &[u8]) {
        self.decoder.push(bytes);
        while let Some(frame) = self.decoder.next_frame() {
            let Ok(frame) = frame else { continue };
            if let Ok((_, Reply::State(s))) = Reply::decode(&frame.payload, self.version) {
                self.fused = FwPose {
                    x: s.px as f32,
                    y: s.py as f32,
                    yaw: s.yaw as f32,
                };
                self.uwb = FwPose {
                    x: s.px_uwb as f32,
                    y: s.py_uwb as f32,
                    yaw: s.yaw as f32,
                };
            }
        }
    }

    fn truth(&self) -> Truth {
        self.plant.truth(self.fused, self.uwb)
    }

    /// Runs the bridge on tokio's clock until the client closes its end or the firmware fails.
    async fn run(mut self, mut stream: DuplexStream, shared: Arc<Mutex<Shared>>) {
        let started = Instant::now();
        let mut buf = vec![0u8; 4096];
        let mut ticks: u64 = 0;
        let result: Result<(), String> = loop {
            let next = started + Duration::from_micros((ticks + 1) * PLANT_TICK_US);
            tokio::select! {
                biased;
                read = stream.read(&mut buf) => match read {
                    Ok(0) | Err(_) => break Ok(()),
                    Ok(n) => {
                        if let Err(e) = self.process.send_car_bytes(&buf[..n]) {
                            break Err(e.to_string());
                        }
                    }
                },
                () = tokio::time::sleep_until(next) => {
                    ticks += 1;
                    let out = match self.tick() {
                        Ok(out) => out,
                        Err(e) => break Err(e.to_string()),
                    };
                    {
                        let mut s = shared.lock().unwrap_or_else(|e| e.into_inner());
                        s.truth = self.truth();
                        s.events.append(&mut self.events);
                    }
                    if !out.is_empty() && stream.write_all(&out).await.is_err() {
                        break Ok(());
                    }
                }
            }
        };
        if let Err(e) = result {
            tracing::error!("the firmware built for the host stopped: {e}");
            shared.lock().unwrap_or_else(|e| e.into_inner()).ended = Some(e);
        }
    }
}

/// The firmware cars of a campaign with a fresh car per test (`run --car sitl:TREE`): test
/// *i*'s car is a fresh start of the executable, its plant seeded as the embedded simulated
/// car's of test *i* (the same noise streams), standing where the runner says.
pub struct SitlCars {
    car: SitlCar,
    seed: u64,
    virtual_time: bool,
}

impl SitlCars {
    /// The cars of a campaign with `seed` on `firmware`, each in the world and with the physics
    /// of `sim` (a scenario's car with its profile applied).
    pub fn new(
        firmware: &HostFirmware,
        sim: &car_sim::SimConfig,
        seed: u64,
        virtual_time: bool,
    ) -> Self {
        Self {
            car: SitlCar {
                executable: firmware.executable.clone(),
                plant: plant_options(firmware, sim),
            },
            seed,
            virtual_time,
        }
    }
}

/// The physical car of the simulated car `sim` driven by `firmware`: `sim`'s world, radio,
/// receiver and sensor errors; the geometry of the configuration the firmware boots with (what
/// it assumes of its car).
pub fn plant_options(firmware: &HostFirmware, sim: &car_sim::SimConfig) -> PlantOptions {
    plant_of(&firmware.config, sim)
}

/// The physical car of `sim` with the geometry of `config`.
fn plant_of(config: &car_sim::FirmwareConfig, sim: &car_sim::SimConfig) -> PlantOptions {
    PlantOptions {
        // The shim's servo driver ramps the output as the board's does (`steering_ramp_time`);
        // the servo follows the output it is sent.
        vehicle: car_sim::VehicleParams {
            steering_ramp_time: 0.0,
            ..config.vehicle
        },
        gnss_antenna: (f64::from(config.gps_ant_x), f64::from(config.gps_ant_y)),
        world: sim.world.clone(),
        radio: sim.radio,
        gnss: sim.gnss,
        sensors: sim.sensors,
        placement: sim.placement.unwrap_or(Placement {
            x: 0.0,
            y: 0.0,
            heading: 0.0,
        }),
        seed: sim.seed,
    }
}

/// Pins the calling thread to one core, once per thread, and so the firmware processes it
/// starts afterwards (a child inherits its thread's CPU mask). In virtual time a test is a
/// ping-pong of pipe round trips between the thread and its firmware (one per 5 ms step); on two
/// cores the kernel wakes each side on the other core, and a cross-core wake-up on a virtual
/// machine costs more than the step's work: 20 tests of seed 1 on the 10.1 tree, `--jobs 1`,
/// took 11.3 s unpinned and 1.9 s under `taskset -c 0` (docs/sitl.md). The core is the one the
/// thread runs on now (where the kernel's balancing put it), so that the threads of several
/// jobs, and of several drivecheck processes, stay spread as the kernel spread them.
pub fn share_a_core_with_the_firmware() {
    #[cfg(target_os = "linux")]
    {
        use nix::sched::{CpuSet, sched_getcpu, sched_setaffinity};
        use nix::unistd::Pid;
        thread_local! {
            static PINNED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
        }
        if PINNED.get() {
            return;
        }
        PINNED.set(true);
        let Ok(cpu) = sched_getcpu() else {
            return;
        };
        let mut set = CpuSet::new();
        if set.set(cpu).is_ok() {
            // Pid 0: the calling thread. A failure leaves the thread as it was: slower, no worse.
            let _ = sched_setaffinity(Pid::from_raw(0), &set);
        }
    }
}

impl FreshCars for SitlCars {
    type Vehicle = Car;

    fn virtual_time(&self) -> bool {
        self.virtual_time
    }

    fn connect(&self, test_index: usize, start: Option<StartPose>) -> Connecting<'_, Car> {
        let mut car = self.car.clone();
        car.plant.seed = campaign::seed::derive(self.seed, Purpose::Simulator { test_index });
        if let Some(start) = start {
            car.plant.placement = Placement {
                x: start.position.x,
                y: start.position.y,
                heading: start.heading,
            };
        }
        if self.virtual_time {
            share_a_core_with_the_firmware();
        }
        Box::pin(async move {
            let (client, handle) = connect_sitl(&car)
                .await
                .map_err(super::ConnectError::Sitl)?;
            Ok((client, Box::new(handle) as Box<dyn SimulatorView>))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_physical_car_has_the_geometry_the_firmware_boots_with() {
        let mut config = car_sim::FirmwareConfig::defaults(FirmwareVersion::V10_1);
        config.vehicle.wheel_diam = 0.13;
        config.vehicle.axis_distance = 0.57;
        config.gps_ant_x = 0.42;
        let firmware = HostFirmware {
            executable: PathBuf::from("sitl-firmware"),
            version: FirmwareVersion::V10_1,
            tree_hash: String::new(),
            config,
        };
        let plant = plant_options(&firmware, &car_sim::SimConfig::default());
        assert_eq!(plant.vehicle.wheel_diam, 0.13);
        assert_eq!(plant.vehicle.axis_distance, 0.57);
        // 10.1 ramps its servo over 0.6 s: the shim's driver does, so the servo follows at once.
        assert_eq!(firmware.config.vehicle.steering_ramp_time, 0.6);
        assert_eq!(plant.vehicle.steering_ramp_time, 0.0);
        assert_eq!(plant.gnss_antenna, (f64::from(0.42_f32), 0.0));
        assert_eq!(
            geometry_differences(&firmware.config, FirmwareVersion::V10_1).as_deref(),
            Some("wheel_diam 0.13 (0.11), axis_distance 0.57 (0.475), gps_ant_x 0.42 (0)")
        );
        assert_eq!(
            geometry_differences(
                &car_sim::FirmwareConfig::defaults(FirmwareVersion::V12_3),
                FirmwareVersion::V12_3
            ),
            None
        );
    }
}
