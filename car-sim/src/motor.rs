//! The HIL motor simulator of the firmware (`docs/firmware.md#motor-simulator`): ramps, friction,
//! tachometer, timeout.

/// Simulation step, s.
pub const MOTOR_DT: f32 = 0.01;
/// Maximum electrical RPM: 39 V · 520 KV · 2.
pub const RPM_MAX: f32 = 39.0 * 520.0 * 2.0;
/// Ramp of the RPM and duty modes, ERPM/s.
const RAMP_ERPM_PER_S: f32 = 25_000.0;
/// Current that gives the full ramp, A.
const REFERENCE_CURRENT: f32 = 80.0;
/// Constant friction, ERPM/s.
const FRICTION_ERPM_PER_S: f32 = 500.0;
/// Time without a command after which the simulator brakes, s.
const TIMEOUT_S: f32 = 2.0;
/// Brake current applied after the timeout, A.
const TIMEOUT_BRAKE_A: f32 = 10.0;
/// Input voltage reported in HIL mode, V.
pub const HIL_V_IN: f32 = 39.0;
/// MOSFET temperature reported in HIL mode, °C.
pub const HIL_TEMP_MOS: f32 = 25.0;

/// A motor command, as the firmware sends it to the motor controller.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotorCommand {
    /// Duty cycle −1..1.
    Duty(f32),
    /// Motor current, A.
    Current(f32),
    /// Brake current, A (the magnitude is used).
    CurrentBrake(f32),
    /// Electrical RPM setpoint.
    Rpm(f32),
    /// Position control (nothing happens in the simulator).
    Position,
}

/// The simulated motor: its mode, RPM, tachometer and timeout timer.
#[derive(Debug, Clone, PartialEq)]
pub struct Motor {
    mode: MotorCommand,
    rpm: f32,
    tacho: f32,
    since_command: f32,
}

impl Default for Motor {
    fn default() -> Self {
        Self {
            mode: MotorCommand::Current(0.0),
            rpm: 0.0,
            tacho: 0.0,
            since_command: 0.0,
        }
    }
}

/// Moves `value` towards `target` by at most `step`, never overshooting.
pub fn step_towards(value: f32, target: f32, step: f32) -> f32 {
    if value < target {
        (value + step).min(target)
    } else if value > target {
        (value - step).max(target)
    } else {
        value
    }
}

impl Motor {
    /// Applies a command: it becomes the mode and clears the timeout timer.
    pub fn command(&mut self, command: MotorCommand) {
        self.mode = command;
        self.since_command = 0.0;
    }

    /// One 10 ms step: the timeout, the mode update, friction and the tachometer.
    pub fn step(&mut self) {
        self.since_command += MOTOR_DT;
        if self.since_command > TIMEOUT_S {
            self.mode = MotorCommand::CurrentBrake(TIMEOUT_BRAKE_A);
        }
        self.rpm = self.mode_update();
        if !matches!(self.mode, MotorCommand::Rpm(_)) {
            self.rpm *= 0.9_f32.powf(MOTOR_DT);
            self.rpm = step_towards(self.rpm, 0.0, FRICTION_ERPM_PER_S * MOTOR_DT);
        }
        self.tacho += self.rpm / 60.0 * MOTOR_DT * 6.0;
    }

    fn mode_update(&self) -> f32 {
        let ramp = RAMP_ERPM_PER_S * MOTOR_DT;
        match self.mode {
            MotorCommand::Duty(d) => step_towards(self.rpm, d * RPM_MAX, ramp),
            MotorCommand::Current(i) => {
                let target = if i < 0.0 { -RPM_MAX } else { RPM_MAX };
                step_towards(self.rpm, target, ramp * i.abs() / REFERENCE_CURRENT)
            }
            MotorCommand::CurrentBrake(i) => {
                step_towards(self.rpm, 0.0, ramp * i.abs() / REFERENCE_CURRENT)
            }
            MotorCommand::Rpm(r) => step_towards(self.rpm, r, ramp),
            MotorCommand::Position => self.rpm,
        }
    }

    /// Electrical RPM now.
    pub fn rpm(&self) -> f32 {
        self.rpm
    }

    /// The reported integer tachometer, `trunc(tacho_f)`.
    pub fn tachometer(&self) -> i32 {
        // Saturating float-to-int conversion: a car that drove 10⁹ counts saturates, never panics.
        self.tacho.trunc() as i32
    }

    /// The reported duty cycle, `rpm / rpm_max`.
    pub fn duty(&self) -> f32 {
        self.rpm / RPM_MAX
    }

    /// The current mode (the last command, or the timeout brake).
    pub fn mode(&self) -> MotorCommand {
        self.mode
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const K_V: f32 = 5.448_26e-4;

    fn speed(m: &Motor) -> f32 {
        m.rpm() * K_V
    }

    #[test]
    fn rpm_mode_ramps_at_13_6_m_per_s2_without_friction() {
        let mut m = Motor::default();
        m.command(MotorCommand::Rpm(10_000.0));
        m.step();
        assert_eq!(m.rpm(), 250.0);
        for _ in 0..99 {
            m.step();
        }
        assert_eq!(m.rpm(), 10_000.0);
        assert!((speed(&m) - 5.448).abs() < 1e-3);
    }

    #[test]
    fn brake_40_a_decelerates_at_about_6_8_m_per_s2() {
        let mut m = Motor::default();
        m.command(MotorCommand::Rpm(10_000.0));
        for _ in 0..100 {
            m.step();
        }
        m.command(MotorCommand::CurrentBrake(40.0));
        let v0 = speed(&m);
        for _ in 0..10 {
            m.step();
        }
        let decel = (v0 - speed(&m)) / 0.1;
        // 6.81 m/s² from the brake plus friction (10 %/s and 0.27 m/s²).
        assert!((7.0..7.8).contains(&decel), "decel {decel}");
    }

    #[test]
    fn timeout_brakes_at_10_a_after_two_seconds_without_command() {
        let mut m = Motor::default();
        m.command(MotorCommand::Rpm(5_000.0));
        for _ in 0..200 {
            m.step();
        }
        assert_eq!(m.mode(), MotorCommand::Rpm(5_000.0));
        m.step();
        assert_eq!(m.mode(), MotorCommand::CurrentBrake(10.0));
        assert!(m.rpm() < 5_000.0);
    }

    #[test]
    fn tachometer_counts_six_per_erpm_minute_and_truncates() {
        let mut m = Motor::default();
        m.command(MotorCommand::Rpm(1_000.0));
        for _ in 0..100 {
            m.step();
        }
        // 4 ramp steps to 1000 ERPM, then 96 steps at 1000: 0.1·(250+500+750+1000)/100 + 96 = 98.5.
        let t = m.tachometer();
        assert_eq!(t, 98);
        m.command(MotorCommand::Rpm(-1_000.0));
        for _ in 0..300 {
            m.step();
        }
        assert!(m.tachometer() < t);
    }

    #[test]
    fn coasting_slows_by_friction_alone() {
        let mut m = Motor::default();
        m.command(MotorCommand::Rpm(5_000.0));
        for _ in 0..100 {
            m.step();
        }
        m.command(MotorCommand::Current(0.0));
        let before = m.rpm();
        m.step();
        let expected = step_towards(before * 0.9_f32.powf(0.01), 0.0, 5.0);
        assert_eq!(m.rpm(), expected);
    }
}
