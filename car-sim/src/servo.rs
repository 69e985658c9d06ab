//! The steering servo: commanded position clamped to 0..1, applied position ramped at 100 Hz.

/// The steering servo.
#[derive(Debug, Clone, PartialEq)]
pub struct Servo {
    commanded: f32,
    applied: f32,
}

impl Servo {
    /// A servo resting at `position`.
    pub fn new(position: f32) -> Self {
        let p = clamp_unit(position);
        Self {
            commanded: p,
            applied: p,
        }
    }

    /// Commands a position; it is clamped to [0, 1] (a NaN command is ignored).
    pub fn command(&mut self, position: f32) {
        if !position.is_nan() {
            self.commanded = clamp_unit(position);
        }
    }

    /// One 10 ms ramp step: move by at most `1 / (100 · ramp_time)`; instant when `ramp_time ≤ 0`.
    pub fn step(&mut self, ramp_time: f32) {
        if ramp_time <= 0.0 {
            self.applied = self.commanded;
            return;
        }
        let max_step = 1.0 / (100.0 * ramp_time);
        self.applied = crate::motor::step_towards(self.applied, self.commanded, max_step);
    }

    /// The applied position now.
    pub fn position(&self) -> f32 {
        self.applied
    }

    /// The last commanded position.
    pub fn commanded(&self) -> f32 {
        self.commanded
    }
}

fn clamp_unit(x: f32) -> f32 {
    x.clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramps_a_full_sweep_in_the_ramp_time() {
        let mut s = Servo::new(0.0);
        s.command(1.0);
        for _ in 0..59 {
            s.step(0.6);
        }
        assert!(s.position() < 1.0);
        s.step(0.6);
        assert!((s.position() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn clamps_commands_and_moves_instantly_without_ramp() {
        let mut s = Servo::new(0.5);
        s.command(7.0);
        s.step(0.0);
        assert_eq!(s.position(), 1.0);
        s.command(-3.0);
        s.command(f32::NAN);
        s.step(0.0);
        assert_eq!(s.position(), 0.0);
    }
}
