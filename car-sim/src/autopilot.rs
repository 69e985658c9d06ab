//! The pure-pursuit autopilot (`docs/firmware.md#autopilot`): route ring, window scan, steering
//! law, speed, end of route, and the replace/clear/activate semantics of both firmware generations.

use crate::config::{ApTimeMode, FirmwareConfig, truncate};
use crate::motor::MotorCommand;
use crate::terminal::scan_i32;
use car_link::firmware::steering::{self, Compensation, LOOK_AHEAD_STRETCHES, PursuitPose};
use car_link::firmware::{FirmwareProfile, FirmwareVersion, RouteEnd};

/// Milliseconds per day.
const MS_PER_DAY: i32 = 86_400_000;
/// Brake current at the route end, A.
const ROUTE_END_BRAKE_A: f32 = 10.0;

/// One stored route point (the 16-byte 10.x layout has no `pz` and no `attributes`; they are 0).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RoutePoint {
    /// East, m.
    pub px: f32,
    /// North, m.
    pub py: f32,
    /// Height, m (unused by the autopilot).
    pub pz: f32,
    /// Speed, m/s.
    pub speed: f32,
    /// Time, ms (time modes only).
    pub time: i32,
    /// 12.x attributes: bits 0–2 select the positioning source.
    pub attributes: u32,
}

impl RoutePoint {
    /// A point at `(px, py)` with a speed, time 0 and no attributes.
    pub fn at(px: f32, py: f32, speed: f32) -> Self {
        Self {
            px,
            py,
            speed,
            ..Self::default()
        }
    }

    fn dist_to(&self, x: f32, y: f32) -> f32 {
        (self.px - x).hypot(self.py - y)
    }

    fn dist(&self, other: &RoutePoint) -> f32 {
        self.dist_to(other.px, other.py)
    }
}

/// A planar pose as the firmware holds it: position in m, yaw in degrees clockwise from east.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FwPose {
    /// East, m.
    pub x: f32,
    /// North, m.
    pub y: f32,
    /// Yaw, degrees, positive clockwise.
    pub yaw: f32,
}

/// What one autopilot cycle reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ApInputs {
    /// The fused (RTK) pose.
    pub fused: FwPose,
    /// The UWB pose.
    pub uwb: FwPose,
    /// Odometry speed, m/s.
    pub speed: f32,
    /// Time of day, ms (−1 when unknown).
    pub ms_today: i32,
}

/// What one autopilot cycle commands.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ApOutput {
    /// A servo position command.
    pub servo: Option<f32>,
    /// A motor command.
    pub motor: Option<MotorCommand>,
    /// A zero-length segment was met in the window (guarded: `docs/firmware.md#uploading-points`).
    pub zero_length_segment: bool,
}

/// The result of storing a packet of points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StoreOutcome {
    /// The packet repeated the previous packet's first point and was dropped (still acked).
    pub dropped_as_duplicate: bool,
    /// The ring overflowed: the write index reached the current segment (points not yet driven
    /// were or will be overwritten).
    pub ring_overflow: bool,
}

/// The route part returned by AP_GET_ROUTE_PART.
#[derive(Debug, Clone, PartialEq)]
pub struct RoutePart {
    /// The ring write index (`point_last`).
    pub route_len: i32,
    /// The requested points; indices outside the stored route are all-zero points.
    pub points: Vec<RoutePoint>,
}

/// The autopilot state.
#[derive(Debug, Clone, PartialEq)]
pub struct Autopilot {
    firmware: FirmwareProfile,
    route: Vec<RoutePoint>,
    active: bool,
    point_last: usize,
    point_now: usize,
    has_prev_point: bool,
    goal: RoutePoint,
    rad_now: f32,
    rx_prev: Option<RoutePoint>,
    route_left: i32,
    start_time: i32,
    started: bool,
    route_end: bool,
    sync_received: bool,
    look_ahead: usize,
    dynamic_rad: bool,
    ang_dist_comp: bool,
    closest_distance: Option<f32>,
}

/// One segment of the window, by ring indices.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Segment {
    start: usize,
    end: usize,
}

/// What the window scans found.
struct Scan {
    goal: RoutePoint,
    speed_segment: Segment,
    closest_start: usize,
    closest_distance: f32,
    zero_length: bool,
}

impl Autopilot {
    /// A freshly booted autopilot: empty route, inactive.
    pub fn new(firmware: FirmwareVersion) -> Self {
        Self {
            firmware: firmware.profile(),
            route: vec![RoutePoint::default(); firmware.profile().route_capacity],
            active: false,
            point_last: 0,
            point_now: 0,
            has_prev_point: false,
            goal: RoutePoint::default(),
            rad_now: -1.0,
            rx_prev: None,
            route_left: 0,
            start_time: 0,
            started: false,
            route_end: false,
            sync_received: false,
            look_ahead: LOOK_AHEAD_STRETCHES,
            dynamic_rad: true,
            ang_dist_comp: true,
            closest_distance: None,
        }
    }

    fn size(&self) -> usize {
        self.route.len()
    }

    /// Whether the autopilot is active.
    pub fn is_active(&self) -> bool {
        self.active
    }

    /// The goal as reported in GET_STATE (`(0, 0)` after a clear).
    pub fn goal(&self) -> (f32, f32) {
        (self.goal.px, self.goal.py)
    }

    /// The look-ahead radius as reported (−1 when inactive or at the route end).
    pub fn rad_now(&self) -> f32 {
        self.rad_now
    }

    /// `ap_route_left` as reported (stale while inactive).
    pub fn route_left(&self) -> i32 {
        self.route_left
    }

    /// `point_now`: start index of the closest segment.
    pub fn point_now(&self) -> usize {
        self.point_now
    }

    /// The distance from the car to the closest point of the route's window at the last cycle,
    /// m: what the firmware prints and plots as "Diff (cm)" with `ap_print_closest n` (every n-th
    /// cycle). `None` when the last cycle looked for no closest point (inactive, fewer than two
    /// points, driving to the start).
    pub fn closest_distance(&self) -> Option<f32> {
        self.closest_distance
    }

    /// `point_last`: the ring write index.
    pub fn point_last(&self) -> usize {
        self.point_last
    }

    /// The stored route point at a ring index.
    pub fn route_point(&self, index: usize) -> Option<&RoutePoint> {
        self.route.get(index)
    }

    // ----- commands -----

    /// AP_ADD_POINTS: the duplicate check on the first point, then store every point.
    pub fn add_points(&mut self, points: &[RoutePoint], cfg: &FirmwareConfig) -> StoreOutcome {
        let mut outcome = StoreOutcome::default();
        let Some((first, rest)) = points.split_first() else {
            return outcome;
        };
        if !self.accept_first(first) {
            outcome.dropped_as_duplicate = true;
            return outcome;
        }
        self.store(*first, cfg, &mut outcome);
        for p in rest {
            self.store(*p, cfg, &mut outcome);
        }
        outcome
    }

    /// AP_REPLACE_ROUTE.
    pub fn replace_route(
        &mut self,
        points: &[RoutePoint],
        cfg: &FirmwareConfig,
        ms_today: i32,
    ) -> StoreOutcome {
        let mut outcome = StoreOutcome::default();
        let Some(first) = points.first() else {
            return outcome;
        };
        if !self.active {
            self.clear(ms_today);
            return self.add_points(points, cfg);
        }
        let time_mode = self.firmware.time_mode_replace
            && cfg.ap_mode_time != ApTimeMode::Speed
            && first.time > 0;
        if time_mode {
            self.replace_in_time_mode(points, cfg, &mut outcome);
            return outcome;
        }
        self.point_last = self.point_now;
        self.has_prev_point = false;
        if self.accept_first(first) {
            self.store(*first, cfg, &mut outcome);
        } else {
            outcome.dropped_as_duplicate = true;
        }
        for p in &points[1..] {
            self.store(*p, cfg, &mut outcome);
        }
        outcome
    }

    /// 12.x time-mode replacement: move back to the newest point not later than the new one; if
    /// a point is refused, the next one is tried as the replacement.
    fn replace_in_time_mode(
        &mut self,
        points: &[RoutePoint],
        cfg: &FirmwareConfig,
        outcome: &mut StoreOutcome,
    ) {
        self.has_prev_point = true;
        for (k, p) in points.iter().enumerate() {
            if k == 0 && !self.accept_first(p) {
                outcome.dropped_as_duplicate = true;
                continue;
            }
            if self.time_replace_one(*p, cfg, outcome) {
                for rest in &points[k + 1..] {
                    self.store(*rest, cfg, outcome);
                }
                return;
            }
        }
    }

    fn time_replace_one(
        &mut self,
        p: RoutePoint,
        cfg: &FirmwareConfig,
        outcome: &mut StoreOutcome,
    ) -> bool {
        let size = self.size();
        for _ in 0..size {
            if self.point_last == self.point_now {
                if p.time < self.route[self.point_now].time {
                    return false;
                }
                self.store(p, cfg, outcome);
                return true;
            }
            let newest = (self.point_last + size - 1) % size;
            self.point_last = newest;
            if self.route[newest].time <= p.time {
                self.store(p, cfg, outcome);
                return true;
            }
        }
        false
    }

    fn accept_first(&mut self, first: &RoutePoint) -> bool {
        if let Some(prev) = self.rx_prev
            && prev.dist(first) < 1e-4
        {
            return false;
        }
        self.rx_prev = Some(*first);
        true
    }

    fn store(&mut self, p: RoutePoint, cfg: &FirmwareConfig, outcome: &mut StoreOutcome) {
        let size = self.size();
        self.route[self.point_last] = p;
        self.point_last = (self.point_last + 1) % size;
        if !self.has_prev_point {
            self.route[(self.point_now + size - 1) % size] = p;
            self.has_prev_point = true;
        }
        if cfg.ap_repeat_routes {
            self.route[size - 1] = p;
        }
        if self.point_last == self.point_now {
            outcome.ring_overflow = true;
        }
    }

    /// AP_REMOVE_LAST_POINT: unless the route is down to the current segment start.
    pub fn remove_last_point(&mut self) {
        if self.point_last != self.point_now {
            self.point_last = (self.point_last + self.size() - 1) % self.size();
        }
    }

    /// AP_CLEAR_POINTS: empty the route and deactivate; `route_left` (and the 12.x started flag)
    /// are kept.
    pub fn clear(&mut self, ms_today: i32) {
        self.active = false;
        self.has_prev_point = false;
        self.point_now = 0;
        self.point_last = 0;
        self.rx_prev = None;
        self.goal = RoutePoint::default();
        self.sync_received = false;
        self.start_time = ms_today;
    }

    /// AP_SET_ACTIVE (with 12.3's `reset_state`; ignored by 10.x).
    pub fn set_active(&mut self, active: bool, reset_state: bool, ms_today: i32) {
        if active && !self.active {
            self.start_time = ms_today;
            self.route_end = false;
        }
        self.active = active;
        if reset_state && self.firmware.set_active_has_reset {
            self.reset_state(ms_today);
        }
    }

    /// Deactivates (RC_CONTROL, watchdog): the flag only.
    pub fn deactivate(&mut self) {
        self.active = false;
    }

    fn reset_state(&mut self, ms_today: i32) {
        self.point_now = 0;
        self.started = false;
        self.route_left = 0;
        self.goal = RoutePoint::default();
        self.sync_received = false;
        self.start_time = ms_today;
    }

    /// AP_GET_ROUTE_PART; `None` (no reply) when `num > 20`.
    pub fn route_part(&self, first: i32, num: u8) -> Option<RoutePart> {
        if num > 20 {
            return None;
        }
        let points = (0..i64::from(num))
            .map(|k| i64::from(first) + k)
            .map(|idx| {
                usize::try_from(idx)
                    .ok()
                    .filter(|&i| i < self.point_last)
                    .map_or_else(RoutePoint::default, |i| self.route[i])
            })
            .collect();
        Some(RoutePart {
            route_len: self.point_last as i32,
            points,
        })
    }

    /// AP_SYNC_POINT: write a speed that reaches route index `point` in `time_ms` into the points
    /// up to it, and switch time mode off until the route is cleared.
    pub fn sync_point(
        &mut self,
        point: i32,
        time_ms: i32,
        min_diff: i32,
        car: FwPose,
        cfg: &FirmwareConfig,
    ) {
        let size = self.size();
        let Ok(target) = usize::try_from(point) else {
            return;
        };
        if target >= size || time_ms < min_diff || time_ms <= 0 {
            return;
        }
        let mut length = 0.0f32;
        let mut index = (self.point_now + 1) % size;
        length += self.route[index].dist_to(car.x, car.y);
        let mut steps = 0;
        while index != target && steps < size {
            let next = (index + 1) % size;
            length += self.route[index].dist(&self.route[next]);
            index = next;
            steps += 1;
        }
        if length < cfg.ap_base_rad {
            return;
        }
        let speed = truncate(
            length / (time_ms as f32 / 1000.0),
            -cfg.ap_max_speed,
            cfg.ap_max_speed,
        );
        let mut i = self.point_now;
        for _ in 0..size {
            self.route[i].speed = speed;
            if i == target {
                break;
            }
            i = (i + 1) % size;
        }
        self.sync_received = true;
    }

    // ----- the control cycle -----

    /// The route length and `route_left`, with the firmware's ring-wrap arithmetic.
    fn route_len_and_left(&self) -> (usize, i32) {
        let size = self.size() as i32;
        let (now, last) = (self.point_now as i32, self.point_last as i32);
        let len = if now > last { size + last - now } else { last };
        let mut left = len - now;
        if left < 0 {
            left += size;
        }
        (len as usize, left)
    }

    /// One 10 ms cycle.
    pub fn cycle(&mut self, cfg: &FirmwareConfig, input: &ApInputs) -> ApOutput {
        self.closest_distance = None;
        if !self.active {
            self.rad_now = -1.0;
            return ApOutput::default();
        }
        let (len, left) = self.route_len_and_left();
        self.route_left = left;
        let car = self.pose_source(cfg, input);
        if len < 2 {
            return match self.firmware.route_end {
                RouteEnd::DeactivatesAndResets => ApOutput::default(),
                RouteEnd::StaysActiveBraking => self.route_end_actions(cfg, input.ms_today),
            };
        }
        let radius = self.radius(cfg, input.speed);
        self.rad_now = radius;
        if self.firmware.drives_to_start && !self.started {
            if self.route[0].dist_to(car.x, car.y) < 1.5 * radius {
                self.started = true;
            } else {
                return self.drive_to_start(cfg, input, car);
            }
        }
        let scan = self.scan(cfg, len, car, radius);
        let last = self.last_index();
        let at_end = !cfg.ap_repeat_routes
            && self.route_left < 3
            && self.route[last].dist_to(car.x, car.y) < radius;
        self.point_now = scan.closest_start;
        self.closest_distance = Some(scan.closest_distance);
        self.goal = scan.goal;
        let mut out = if at_end {
            self.route_end_actions(cfg, input.ms_today)
        } else {
            let speed = self.speed(cfg, input, car, scan.speed_segment);
            self.drive(cfg, input.speed, car, speed)
        };
        out.zero_length_segment = scan.zero_length;
        out
    }

    fn last_index(&self) -> usize {
        (self.point_last + self.size() - 1) % self.size()
    }

    fn pose_source(&self, cfg: &FirmwareConfig, input: &ApInputs) -> FwPose {
        let use_uwb = self.firmware.selects_position_source && {
            let attr = if self.started {
                self.route[self.point_now].attributes & 0b111
            } else {
                0
            };
            match attr {
                1 => false,
                2 => true,
                _ => cfg.vehicle.use_uwb_pos,
            }
        };
        if use_uwb { input.uwb } else { input.fused }
    }

    fn radius(&self, cfg: &FirmwareConfig, speed: f32) -> f32 {
        if !self.dynamic_rad {
            return cfg.ap_base_rad;
        }
        steering::look_ahead_radius(
            self.firmware.look_ahead,
            cfg.ap_base_rad,
            cfg.ap_rad_time_ahead,
            speed,
        )
    }

    fn drive_to_start(&mut self, cfg: &FirmwareConfig, input: &ApInputs, car: FwPose) -> ApOutput {
        self.point_now = 0;
        self.goal = self.route[0];
        let speed = self.route[0].speed;
        self.drive(cfg, input.speed, car, speed)
    }

    /// The window's segment `i` (an unwrapped index), wrapped as the firmware does.
    fn wrap(&self, i: usize) -> usize {
        let mut ind = i;
        if ind >= self.point_last {
            if self.point_now <= self.point_last {
                ind -= self.point_last;
            } else if ind >= self.size() {
                ind -= self.size();
            }
        }
        ind % self.size()
    }

    fn window(&self, len: usize) -> impl Iterator<Item = Segment> + '_ {
        self.window_indices(len).map(|i| self.segment(i))
    }

    /// The unwrapped indices of the scan window's segments (see [`Self::segment`]).
    fn window_indices(&self, len: usize) -> std::ops::Range<usize> {
        let cap = if self.firmware.scan_stops_before_last_point {
            len - 1
        } else {
            len
        };
        let k = self.look_ahead.min(cap);
        self.point_now..self.point_now + k
    }

    fn segment(&self, i: usize) -> Segment {
        Segment {
            start: self.wrap(i),
            end: self.wrap(i + 1),
        }
    }

    fn scan(&mut self, cfg: &FirmwareConfig, len: usize, car: FwPose, radius: f32) -> Scan {
        let last = self.last_index();
        let repeat = cfg.ap_repeat_routes;
        let mut goal = None;
        let mut hit_segment = None;
        let mut last_point_reached = false;
        let mut zero_length = false;
        // By index: the loop writes a point's time, which a borrowing iterator would not allow.
        for i in self.window_indices(len) {
            let seg = self.segment(i);
            let (p1, p2) = (self.route[seg.start], self.route[seg.end]);
            if repeat && time_before(p2.time, p1.time) {
                let mut t = p2.time.wrapping_add(cfg.ap_time_add_repeat_ms);
                if t > MS_PER_DAY {
                    t -= MS_PER_DAY;
                }
                self.route[seg.end].time = t;
            }
            let hit = circle_segment_goal(car, radius, &p1, &p2);
            zero_length |= p1.dist(&p2).powi(2) <= 1e-6;
            if let Some(g) = hit {
                goal = Some(g);
                hit_segment = Some(seg);
            }
            if !repeat && seg.end == last && goal.is_some() {
                last_point_reached = hit.is_some();
                break;
            }
        }
        let (closest, closest_seg) = self.closest(len, car, repeat, last);
        let closest_distance = closest.dist_to(car.x, car.y);
        let goal_point = if last_point_reached {
            self.route[last]
        } else {
            goal.unwrap_or(closest)
        };
        Scan {
            goal: goal_point,
            speed_segment: hit_segment.unwrap_or(closest_seg),
            closest_start: closest_seg.start,
            closest_distance,
            zero_length,
        }
    }

    fn closest(&self, len: usize, car: FwPose, repeat: bool, last: usize) -> (RoutePoint, Segment) {
        let mut best: Option<(f32, RoutePoint, Segment)> = None;
        for seg in self.window(len) {
            let p = closest_point_on_segment(&self.route[seg.start], &self.route[seg.end], car);
            let d = p.dist_to(car.x, car.y);
            if best.as_ref().is_none_or(|(bd, _, _)| d < *bd) {
                best = Some((d, p, seg));
            }
            if !repeat && seg.end == last {
                break;
            }
        }
        let fallback = Segment { start: 0, end: 1 };
        best.map_or((self.route[0], fallback), |(_, p, s)| (p, s))
    }

    fn speed(&self, cfg: &FirmwareConfig, input: &ApInputs, car: FwPose, seg: Segment) -> f32 {
        let (a, b) = (self.route[seg.start], self.route[seg.end]);
        let goal = self.goal;
        if cfg.ap_mode_time == ApTimeMode::Speed || self.sync_received {
            let da = goal.dist(&a);
            let total = da + goal.dist(&b);
            if total <= 0.0 || !total.is_finite() {
                return a.speed;
            }
            return a.speed + da / total * (b.speed - a.speed);
        }
        self.time_mode_speed(cfg, input, car, a, b)
    }

    fn time_mode_speed(
        &self,
        cfg: &FirmwareConfig,
        input: &ApInputs,
        car: FwPose,
        a: RoutePoint,
        b: RoutePoint,
    ) -> f32 {
        if input.ms_today < 0 {
            return 0.0;
        }
        let goal = self.goal;
        let dist_prev = (goal.dist(&a) * 1000.0) as i32;
        let dist_tot = dist_prev.saturating_add((goal.dist(&b) * 1000.0) as i32);
        let t_goal = map_int(dist_prev, 0, dist_tot, a.time, b.time);
        let mut dt = t_goal.wrapping_sub(input.ms_today);
        if cfg.ap_mode_time == ApTimeMode::RelativeToStart {
            dt = dt.wrapping_add(self.start_time);
        }
        if dt < 0 {
            dt = dt.wrapping_add(MS_PER_DAY);
        }
        if dt == 0 {
            return 0.0;
        }
        goal.dist_to(car.x, car.y) / (dt as f32 / 1000.0)
    }

    fn drive(&self, cfg: &FirmwareConfig, odo_speed: f32, car: FwPose, speed: f32) -> ApOutput {
        let v = &cfg.vehicle;
        let compensation = match self.ang_dist_comp {
            false => Compensation::Off,
            #[cfg(test)]
            true if experiment::multiply_angle() => Compensation::MultiplyAngle2016,
            true => Compensation::DivideRadius,
        };
        let pose = PursuitPose {
            x: car.x,
            y: car.y,
            heading: -car.yaw.to_radians(),
        };
        let mut angle = steering::pursuit_angle(
            pose,
            self.goal.px,
            self.goal.py,
            v.axis_distance,
            compensation,
        );
        let max = steering::max_steering_angle(v.steering_max_angle_rad, odo_speed);
        angle = truncate(angle, -max, max);
        let speed = truncate(speed, -cfg.ap_max_speed, cfg.ap_max_speed);
        let motor =
            (!v.disable_motor).then(|| MotorCommand::Rpm((speed / v.speed_per_erpm()).trunc()));
        ApOutput {
            servo: Some(v.servo_for_angle(angle)),
            motor,
            zero_length_segment: false,
        }
    }

    fn route_end_actions(&mut self, cfg: &FirmwareConfig, ms_today: i32) -> ApOutput {
        self.rad_now = -1.0;
        let out = ApOutput {
            servo: Some(cfg.vehicle.steering_center),
            motor: (!cfg.vehicle.disable_motor)
                .then_some(MotorCommand::CurrentBrake(ROUTE_END_BRAKE_A)),
            zero_length_segment: false,
        };
        if self.firmware.route_end == RouteEnd::DeactivatesAndResets {
            self.active = false;
            self.route_end = true;
            self.reset_state(ms_today);
        }
        out
    }

    // ----- terminal -----

    /// Runs one of the `ap_*` terminal commands; `None` if `args[0]` is not one of them.
    pub fn terminal(&mut self, args: &[&str]) -> Option<Vec<String>> {
        let reply = match *args.first()? {
            "ap_set_look_ahead" => self.cmd_look_ahead(args),
            "ap_dynamic_rad" => on_off(args, |on| {
                self.dynamic_rad = on;
                "OK\n".to_string()
            }),
            "ap_ang_dist_comp" => on_off(args, |on| {
                self.ang_dist_comp = on;
                format!(
                    "Angle distance compensation {}\n",
                    if on { "enabled" } else { "disabled" }
                )
            }),
            "ap_state" => self.state_text(),
            _ => return None,
        };
        Some(vec![reply])
    }

    fn cmd_look_ahead(&mut self, args: &[&str]) -> String {
        if args.len() != 2 {
            return "Wrong number of arguments\n".to_string();
        }
        match scan_i32(args[1]) {
            Some(n) if n >= 1 => {
                self.look_ahead = n as usize;
                format!("Now looking {n} points ahead along the route")
            }
            _ => "Invalid argument\n".to_string(),
        }
    }

    fn state_text(&self) -> String {
        let mut s = format!(
            "m_is_active: {}\nm_has_prev_point: {}\nm_point_now: {}\nm_point_last: {}\n\
             m_point_rx_prev_set: {}\nm_start_time: {}\nm_route_left: {}\n",
            i32::from(self.active),
            i32::from(self.has_prev_point),
            self.point_now,
            self.point_last,
            i32::from(self.rx_prev.is_some()),
            self.start_time,
            self.route_left
        );
        if self.firmware.route_end == RouteEnd::DeactivatesAndResets {
            s.push_str(&format!("m_route_end: {}\n", i32::from(self.route_end)));
        }
        s
    }
}

fn on_off(args: &[&str], mut set: impl FnMut(bool) -> String) -> String {
    if args.len() != 2 {
        return "Wrong number of arguments\n".to_string();
    }
    match args[1] {
        "0" => set(false),
        "1" => set(true),
        other => format!("Invalid argument {other}\n"),
    }
}

/// Whether time of day `t1` is before `t2`, across midnight.
fn time_before(t1: i32, t2: i32) -> bool {
    let mut d = i64::from(t2) - i64::from(t1);
    let half = i64::from(MS_PER_DAY / 2);
    if d > half {
        d -= i64::from(MS_PER_DAY);
    } else if d < -half {
        d += i64::from(MS_PER_DAY);
    }
    d > 0
}

/// Integer linear map (guarded against an empty input range).
fn map_int(x: i32, in_min: i32, in_max: i32, out_min: i32, out_max: i32) -> i32 {
    let span = i64::from(in_max) - i64::from(in_min);
    if span == 0 {
        return out_min;
    }
    let v = (i64::from(x) - i64::from(in_min)) * (i64::from(out_max) - i64::from(out_min)) / span
        + i64::from(out_min);
    v.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

/// The circle–segment goal: with one intersection that one, with two the one nearer the end; no
/// solution for zero-length segments.
fn circle_segment_goal(
    car: FwPose,
    radius: f32,
    p1: &RoutePoint,
    p2: &RoutePoint,
) -> Option<RoutePoint> {
    let (dx, dy) = (p2.px - p1.px, p2.py - p1.py);
    let a = dx * dx + dy * dy;
    if a <= 1e-6 {
        return None;
    }
    let (fx, fy) = (p1.px - car.x, p1.py - car.y);
    let b = 2.0 * (fx * dx + fy * dy);
    let c = fx * fx + fy * fy - radius * radius;
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 || !disc.is_finite() {
        return None;
    }
    let root = disc.sqrt();
    let at = |t: f32| RoutePoint {
        px: p1.px + t * dx,
        py: p1.py + t * dy,
        ..*p1
    };
    let hits: Vec<RoutePoint> = [(-b - root) / (2.0 * a), (-b + root) / (2.0 * a)]
        .into_iter()
        .filter(|t| (0.0..=1.0).contains(t))
        .map(at)
        .collect();
    match hits.as_slice() {
        [] => None,
        [one] => Some(*one),
        [first, second, ..] => Some(if first.dist(p2) < second.dist(p2) {
            *first
        } else {
            *second
        }),
    }
}

/// The point of segment `p1–p2` closest to the car (parameter clamped to [0, 1]); a zero-length
/// segment gives its point (the firmware computes 0/0 here).
fn closest_point_on_segment(p1: &RoutePoint, p2: &RoutePoint, car: FwPose) -> RoutePoint {
    let (dx, dy) = (p2.px - p1.px, p2.py - p1.py);
    let len2 = dx * dx + dy * dy;
    if len2 <= 0.0 {
        return *p1;
    }
    let t = (((car.x - p1.px) * dx + (car.y - p1.py) * dy) / len2).clamp(0.0, 1.0);
    RoutePoint {
        px: p1.px + t * dx,
        py: p1.py + t * dy,
        ..*p1
    }
}

/// Test-only experiments on the steering law, per thread (each test runs on its own thread).
#[cfg(test)]
pub(crate) mod experiment {
    use std::cell::Cell;

    thread_local! {
        static MULTIPLY_ANGLE: Cell<bool> = const { Cell::new(false) };
    }

    /// Whether this thread's cars apply the distance compensation the 2016 way (multiplying the
    /// steering angle) instead of the documented way (dividing the pursuit radius).
    pub(crate) fn multiply_angle() -> bool {
        MULTIPLY_ANGLE.with(Cell::get)
    }

    /// Switches this thread's distance compensation to the 2016 law (`true`) or back.
    pub(crate) fn set_multiply_angle(on: bool) {
        MULTIPLY_ANGLE.with(|c| c.set(on));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(fw: FirmwareVersion, repeat: bool) -> FirmwareConfig {
        let mut c = FirmwareConfig::defaults(fw);
        c.ap_repeat_routes = repeat;
        c
    }

    fn straight(n: usize, speed: f32) -> Vec<RoutePoint> {
        (0..n)
            .map(|i| RoutePoint::at(i as f32, 0.0, speed))
            .collect()
    }

    fn inputs(x: f32, y: f32, yaw: f32, speed: f32) -> ApInputs {
        let pose = FwPose { x, y, yaw };
        ApInputs {
            fused: pose,
            uwb: pose,
            speed,
            ms_today: -1,
        }
    }

    #[test]
    fn route_left_counts_from_the_current_segment_start_to_the_end() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        ap.add_points(&straight(10, 1.0), &c);
        ap.set_active(true, false, 0);
        ap.cycle(&c, &inputs(0.2, 0.0, 0.0, 0.0));
        assert_eq!(ap.route_left(), 10);
        assert_eq!(ap.point_now(), 0);
        ap.cycle(&c, &inputs(5.5, 0.0, 0.0, 0.0));
        assert_eq!(ap.point_now(), 5);
        ap.cycle(&c, &inputs(5.5, 0.0, 0.0, 0.0));
        assert_eq!(ap.route_left(), 5);
    }

    #[test]
    fn the_closest_distance_is_the_car_s_distance_to_the_route_while_active() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        ap.add_points(&straight(10, 1.0), &c);
        ap.cycle(&c, &inputs(2.5, 0.3, 0.0, 0.0));
        assert_eq!(ap.closest_distance(), None);
        ap.set_active(true, false, 0);
        ap.cycle(&c, &inputs(2.5, 0.3, 0.0, 0.0));
        let d = ap.closest_distance().unwrap();
        assert!((d - 0.3).abs() < 1e-6, "{d}");
        ap.deactivate();
        ap.cycle(&c, &inputs(2.5, 0.3, 0.0, 0.0));
        assert_eq!(ap.closest_distance(), None);
    }

    #[test]
    fn radius_rule_per_era() {
        let ap10 = Autopilot::new(FirmwareVersion::V10_1);
        let ap12 = Autopilot::new(FirmwareVersion::V12_3);
        let c10 = FirmwareConfig::defaults(FirmwareVersion::V10_1);
        let c12 = FirmwareConfig::defaults(FirmwareVersion::V12_3);
        assert!((ap10.radius(&c10, 1.0) - 1.323).abs() < 1e-3);
        assert!((ap10.radius(&c10, 2.0) - 1.452).abs() < 1e-3);
        assert!((ap12.radius(&c12, 1.0) - 0.8).abs() < 1e-6);
        assert!((ap12.radius(&c12, 2.0) - 1.6).abs() < 1e-6);
    }

    #[test]
    fn goal_is_the_last_circle_hit_and_speed_is_interpolated_at_the_goal() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        let mut pts = straight(10, 1.0);
        pts[2].speed = 3.0;
        ap.add_points(&pts, &c);
        ap.set_active(true, false, 0);
        let out = ap.cycle(&c, &inputs(0.5, 0.0, 0.0, 0.0));
        let (gx, gy) = ap.goal();
        assert!((gx - 1.7).abs() < 1e-5 && gy.abs() < 1e-6, "goal {gx},{gy}");
        // Goal at 1.7 on segment 1→2: speed 1 + 0.7·2 = 2.4 m/s.
        let rpm = (2.4f32 / c.vehicle.speed_per_erpm()).trunc();
        match out.motor {
            Some(MotorCommand::Rpm(r)) => assert!((r - rpm).abs() <= 1.0, "{r} vs {rpm}"),
            other => panic!("expected an RPM command, got {other:?}"),
        }
        assert!((out.servo.unwrap() - c.vehicle.steering_center).abs() < 1e-6);
    }

    #[test]
    fn end_of_route_10x_stays_active_and_brakes_every_cycle() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        ap.add_points(&straight(5, 1.0), &c);
        ap.set_active(true, false, 0);
        // The first cycle moves point_now to 3; route_left is then 2 < 3.
        ap.cycle(&c, &inputs(3.8, 0.0, 0.0, 0.0));
        for _ in 0..3 {
            let out = ap.cycle(&c, &inputs(3.8, 0.0, 0.0, 0.0));
            assert_eq!(out.motor, Some(MotorCommand::CurrentBrake(10.0)));
            assert_eq!(out.servo, Some(c.vehicle.steering_center));
        }
        assert!(ap.is_active());
        assert_eq!(ap.rad_now(), -1.0);
        // Appending resumes the drive.
        ap.add_points(
            &[
                RoutePoint::at(5.0, 0.0, 1.0),
                RoutePoint::at(6.0, 0.0, 1.0),
                RoutePoint::at(7.0, 0.0, 1.0),
            ],
            &c,
        );
        let out = ap.cycle(&c, &inputs(3.8, 0.0, 0.0, 0.0));
        assert!(matches!(out.motor, Some(MotorCommand::Rpm(_))));
    }

    #[test]
    fn end_of_route_12_3_deactivates_resets_and_redrives_from_route_0() {
        let c = cfg(FirmwareVersion::V12_3, false);
        let mut ap = Autopilot::new(FirmwareVersion::V12_3);
        ap.add_points(&straight(5, 1.0), &c);
        ap.set_active(true, false, 0);
        ap.cycle(&c, &inputs(0.0, 0.0, 0.0, 0.0));
        let first = ap.cycle(&c, &inputs(3.8, 0.0, 0.0, 0.0));
        assert!(matches!(first.motor, Some(MotorCommand::Rpm(_))));
        let out = ap.cycle(&c, &inputs(3.8, 0.0, 0.0, 0.0));
        assert_eq!(out.motor, Some(MotorCommand::CurrentBrake(10.0)));
        assert!(!ap.is_active());
        assert_eq!(
            (ap.route_left(), ap.point_now(), ap.goal()),
            (0, 0, (0.0, 0.0))
        );
        ap.set_active(true, false, 0);
        ap.cycle(&c, &inputs(3.8, 0.0, 0.0, 0.0));
        assert_eq!(ap.goal(), (0.0, 0.0), "heads for route[0] first");
    }

    #[test]
    fn short_route_10x_brakes_12x_does_nothing() {
        for (fw, expect_brake) in [
            (FirmwareVersion::V10_1, true),
            (FirmwareVersion::V12_3, false),
        ] {
            let c = cfg(fw, false);
            let mut ap = Autopilot::new(fw);
            ap.add_points(&straight(1, 1.0), &c);
            ap.set_active(true, false, 0);
            let out = ap.cycle(&c, &inputs(0.0, 0.0, 0.0, 0.0));
            assert_eq!(out.motor.is_some(), expect_brake, "{fw}");
        }
    }

    #[test]
    fn duplicate_first_point_drops_the_packet_and_clear_forgets() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        let pkt = straight(5, 1.0);
        assert!(!ap.add_points(&pkt, &c).dropped_as_duplicate);
        assert!(ap.add_points(&pkt, &c).dropped_as_duplicate);
        assert_eq!(ap.point_last(), 5);
        ap.clear(0);
        assert!(!ap.add_points(&pkt, &c).dropped_as_duplicate);
        assert_eq!(ap.point_last(), 5);
    }

    #[test]
    fn clear_keeps_route_left_and_zeroes_the_goal() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        ap.add_points(&straight(10, 1.0), &c);
        ap.set_active(true, false, 0);
        ap.cycle(&c, &inputs(0.5, 0.0, 0.0, 0.0));
        ap.clear(0);
        assert!(!ap.is_active());
        assert_eq!(ap.route_left(), 10);
        assert_eq!(ap.goal(), (0.0, 0.0));
        ap.cycle(&c, &inputs(0.5, 0.0, 0.0, 0.0));
        assert_eq!(ap.rad_now(), -1.0);
    }

    #[test]
    fn replace_while_active_cuts_back_to_the_current_segment() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        ap.add_points(&straight(10, 1.0), &c);
        ap.set_active(true, false, 0);
        ap.cycle(&c, &inputs(3.5, 0.0, 0.0, 0.0));
        assert_eq!(ap.point_now(), 3);
        let new: Vec<RoutePoint> = (0..3)
            .map(|i| RoutePoint::at(3.0 + i as f32, 1.0, 1.0))
            .collect();
        ap.replace_route(&new, &c, 0);
        assert_eq!(ap.point_last(), 6);
        assert_eq!(ap.route_point(3).unwrap().py, 1.0);
        assert!(ap.is_active());
    }

    #[test]
    fn route_part_refuses_more_than_20_and_zeroes_missing_points() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        ap.add_points(&straight(3, 1.0), &c);
        assert!(ap.route_part(0, 21).is_none());
        let part = ap.route_part(1, 4).unwrap();
        assert_eq!(part.route_len, 3);
        assert_eq!(part.points[0].px, 1.0);
        assert_eq!(part.points[2], RoutePoint::default());
        assert_eq!(
            ap.route_part(-5, 1).unwrap().points[0],
            RoutePoint::default()
        );
    }

    #[test]
    fn ring_overflow_overwrites_and_is_flagged() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        let mut overflow = false;
        for k in 0..101 {
            let pts: Vec<RoutePoint> = (0..5)
                .map(|i| RoutePoint::at((k * 5 + i) as f32, 0.0, 1.0))
                .collect();
            overflow |= ap.add_points(&pts, &c).ring_overflow;
        }
        assert!(overflow);
        assert_eq!(ap.point_last(), 5);
        assert_eq!(ap.route_point(0).unwrap().px, 500.0);
    }

    #[test]
    fn zero_length_segments_are_guarded_and_flagged() {
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        let pts = [
            RoutePoint::at(0.0, 0.0, 1.0),
            RoutePoint::at(0.0, 0.0, 1.0),
            RoutePoint::at(1.0, 0.0, 1.0),
            RoutePoint::at(2.0, 0.0, 1.0),
            RoutePoint::at(3.0, 0.0, 1.0),
        ];
        ap.add_points(&pts, &c);
        ap.set_active(true, false, 0);
        let out = ap.cycle(&c, &inputs(0.0, 0.1, 0.0, 0.0));
        assert!(out.zero_length_segment);
        assert!(out.servo.is_some_and(f32::is_finite));
    }

    #[test]
    fn past_the_end_circle_the_scan_wraps_onto_the_segment_back_to_route_0() {
        // The scan wraps past the route end (`docs/firmware.md#control-cycle`): an L-shaped route;
        // the car stands beyond the route-end circle, next to the wrapped segment from the last
        // point back to route[0].
        let c = cfg(FirmwareVersion::V10_1, false);
        let mut ap = Autopilot::new(FirmwareVersion::V10_1);
        let mut pts: Vec<RoutePoint> = (0..6).map(|i| RoutePoint::at(i as f32, 0.0, 1.0)).collect();
        pts.extend((1..5).map(|j| RoutePoint::at(5.0, j as f32, 1.0)));
        ap.add_points(&pts, &c);
        ap.set_active(true, false, 0);
        ap.cycle(&c, &inputs(5.0, 3.5, -90.0, 0.0));
        ap.cycle(&c, &inputs(5.0, 3.5, -90.0, 0.0));
        assert_eq!(ap.point_now(), 8);
        let out = ap.cycle(&c, &inputs(3.2, 2.0, 0.0, 0.0));
        let (gx, gy) = ap.goal();
        assert!(
            (gy - 0.8 * gx).abs() < 1e-4,
            "goal ({gx}, {gy}) on the way back to route[0]"
        );
        assert!(matches!(out.motor, Some(MotorCommand::Rpm(_))));
    }

    #[test]
    fn terminal_texts() {
        let mut ap = Autopilot::new(FirmwareVersion::V12_3);
        assert_eq!(
            ap.terminal(&["ap_set_look_ahead", "4"]).unwrap(),
            ["Now looking 4 points ahead along the route"]
        );
        assert_eq!(
            ap.terminal(&["ap_set_look_ahead", "0"]).unwrap(),
            ["Invalid argument\n"]
        );
        assert_eq!(
            ap.terminal(&["ap_set_look_ahead"]).unwrap(),
            ["Wrong number of arguments\n"]
        );
        assert_eq!(ap.terminal(&["ap_dynamic_rad", "0"]).unwrap(), ["OK\n"]);
        assert_eq!(
            ap.terminal(&["ap_dynamic_rad", "x"]).unwrap(),
            ["Invalid argument x\n"]
        );
        assert_eq!(
            ap.terminal(&["ap_ang_dist_comp", "1"]).unwrap(),
            ["Angle distance compensation enabled\n"]
        );
        assert_eq!(
            ap.terminal(&["ap_ang_dist_comp", "0"]).unwrap(),
            ["Angle distance compensation disabled\n"]
        );
        let state = &ap.terminal(&["ap_state"]).unwrap()[0];
        assert!(state.starts_with("m_is_active: 0\nm_has_prev_point: 0\n"));
        assert!(state.ends_with("m_route_left: 0\nm_route_end: 0\n"));
        assert!(ap.terminal(&["ping"]).is_none());
    }
}
