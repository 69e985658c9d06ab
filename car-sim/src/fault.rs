//! Fault injection (`docs/firmware.md#fault-injection`): 5 probes × 5 slots, never freed, evaluated
//! in slot order.

use crate::terminal::{scan_f32, scan_i32};

pub use car_link::fault::MAX_PROBE_ID as MAX_ID_LEN;
pub use car_link::firmware::{FAULT_PROBES as PROBES, FAULTS_PER_PROBE as SLOTS_PER_PROBE};

/// The fault types and what each does to a value (the firmware model's table,
/// `car_link::firmware::KINDS`, shared with the orchestrator's client).
pub use car_link::FaultKind;

/// One fault slot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultSlot {
    /// The fault type.
    pub kind: FaultKind,
    /// Its parameter.
    pub param: f32,
    /// Whether the slot is taken (expired faults stay taken).
    pub active: bool,
    /// Absolute start iteration (`start + iteration at the add`).
    pub start_it: i32,
    /// Duration in iterations; 0 = permanent, negative = never.
    pub duration: i32,
}

impl FaultSlot {
    const EMPTY: Self = Self {
        kind: FaultKind::None,
        param: 0.0,
        active: false,
        start_it: 0,
        duration: 0,
    };

    fn applies_at(&self, iteration: i32) -> bool {
        self.active
            && iteration >= self.start_it
            && (self.duration == 0 || self.duration > iteration.wrapping_sub(self.start_it))
    }
}

/// One probe: an id, its iteration counter and its fault slots.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// The id (keeps its value after `fi_clear_faults`).
    pub id: String,
    /// Whether the probe is in use.
    pub active: bool,
    /// Number of evaluations while fault injection was enabled.
    pub iteration: i32,
    /// The fault slots, in application order.
    pub slots: [FaultSlot; SLOTS_PER_PROBE],
}

impl Probe {
    fn empty() -> Self {
        Self {
            id: String::new(),
            active: false,
            iteration: 0,
            slots: [FaultSlot::EMPTY; SLOTS_PER_PROBE],
        }
    }
}

/// The value after a probe, and which slots applied (bit `i` = slot `i`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeOutcome {
    /// The value after all applying faults.
    pub value: f32,
    /// Bit mask of the slots that applied.
    pub applied_slots: u8,
    /// The probe's iteration at which it was evaluated (before the increment).
    pub iteration: i32,
}

/// Why `fi_add_fault` refused a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AddFaultError {
    /// The probe id has more than 20 characters.
    #[error("probe id longer than 20 characters")]
    IdTooLong,
    /// All 5 slots of the probe are taken.
    #[error("too many faults on this probe")]
    NoFreeSlot,
    /// All 5 probes are in use by other ids.
    #[error("too many probes in use")]
    NoFreeProbe,
}

/// The fault-injection state of the firmware.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultInjection {
    enabled: bool,
    probes: Vec<Probe>,
}

impl Default for FaultInjection {
    fn default() -> Self {
        Self {
            enabled: false,
            probes: (0..PROBES).map(|_| Probe::empty()).collect(),
        }
    }
}

impl FaultInjection {
    /// Whether fault injection is enabled (off at boot).
    pub fn is_enabled(&self) -> bool {
        self.enabled
    }

    /// Switches fault injection on or off; off freezes the counters and suspends all faults.
    pub fn set_enabled(&mut self, enabled: bool) {
        self.enabled = enabled;
    }

    /// The fault slots taken (expired faults included: they keep their slot until
    /// `fi_clear_faults`).
    pub fn faults_armed(&self) -> usize {
        self.probes
            .iter()
            .filter(|p| p.active)
            .flat_map(|p| p.slots.iter())
            .filter(|s| s.active)
            .count()
    }

    /// The probes, in slot order.
    pub fn probes(&self) -> &[Probe] {
        &self.probes
    }

    /// Passes `value` through probe `id`: when enabled, applies the due faults of every active
    /// probe with that id in slot order and advances its counter.
    pub fn evaluate(&mut self, id: &str, value: f32) -> ProbeOutcome {
        let mut outcome = ProbeOutcome {
            value,
            applied_slots: 0,
            iteration: 0,
        };
        if !self.enabled {
            return outcome;
        }
        for probe in self.probes.iter_mut().filter(|p| p.active && p.id == id) {
            outcome.iteration = probe.iteration;
            for (i, slot) in probe.slots.iter().enumerate() {
                if slot.applies_at(probe.iteration) {
                    let elapsed = probe.iteration.wrapping_sub(slot.start_it).unsigned_abs();
                    outcome.value = slot.kind.apply(outcome.value, slot.param, elapsed);
                    outcome.applied_slots |= 1 << i;
                }
            }
            probe.iteration = probe.iteration.wrapping_add(1);
        }
        outcome
    }

    /// Adds a fault the way `fi_add_fault` does (the id length is checked by the caller's text
    /// handling as well; it is checked here too so the typed API never stores a longer id).
    pub fn add(
        &mut self,
        id: &str,
        kind: FaultKind,
        param: f32,
        start: i32,
        duration: i32,
    ) -> Result<(), AddFaultError> {
        if id.len() > MAX_ID_LEN {
            return Err(AddFaultError::IdTooLong);
        }
        let index = self.probe_for(id).ok_or(AddFaultError::NoFreeProbe)?;
        let probe = &mut self.probes[index];
        probe.active = true;
        let slot = probe
            .slots
            .iter_mut()
            .find(|s| !s.active)
            .ok_or(AddFaultError::NoFreeSlot)?;
        *slot = FaultSlot {
            kind,
            param,
            active: true,
            start_it: start.wrapping_add(probe.iteration),
            duration,
        };
        Ok(())
    }

    /// The probe with this id (even a cleared one), else the first inactive probe renamed to it.
    fn probe_for(&mut self, id: &str) -> Option<usize> {
        if let Some(i) = self.probes.iter().position(|p| p.id == id) {
            return Some(i);
        }
        let i = self.probes.iter().position(|p| !p.active)?;
        self.probes[i].id = id.to_string();
        Some(i)
    }

    /// `fi_clear_faults`: deactivates all probes and faults and zeroes the counters.
    pub fn clear(&mut self) {
        for probe in &mut self.probes {
            probe.active = false;
            probe.iteration = 0;
            for slot in &mut probe.slots {
                slot.active = false;
            }
        }
    }

    /// `fi_reset_cnt`: zeroes the counters (start iterations stay absolute).
    pub fn reset_counters(&mut self) {
        for probe in &mut self.probes {
            probe.iteration = 0;
        }
    }

    /// Runs one of the `fi_*` terminal commands; `None` if `args[0]` is not one of them.
    pub fn terminal(&mut self, args: &[&str]) -> Option<Vec<String>> {
        let out = match *args.first()? {
            "fi_set_enabled" => vec![self.cmd_set_enabled(args)],
            "fi_add_fault" => self.cmd_add_fault(args),
            "fi_clear_faults" => {
                self.clear();
                vec!["Faults cleared\n".to_string()]
            }
            "fi_print_faults" => self.cmd_print_faults(),
            "fi_reset_cnt" => {
                self.reset_counters();
                vec!["Probe iteration counters reset".to_string()]
            }
            _ => return None,
        };
        Some(out)
    }

    fn cmd_set_enabled(&mut self, args: &[&str]) -> String {
        if args.len() != 2 {
            return "Wrong number of arguments\n".to_string();
        }
        match args[1] {
            "0" => {
                self.enabled = false;
                "Fault Injection disabled\n".to_string()
            }
            "1" => {
                self.enabled = true;
                "Fault Injection enabled\n".to_string()
            }
            other => format!("Invalid argument {other}\n"),
        }
    }

    fn cmd_add_fault(&mut self, args: &[&str]) -> Vec<String> {
        if args.len() != 6 {
            return vec!["Wrong number of arguments\n".to_string()];
        }
        let (id, type_text) = (args[1], args[2]);
        let mut out = Vec::new();
        if id.len() > MAX_ID_LEN {
            out.push(format!("Too long ID. Maximum length is {MAX_ID_LEN}\n"));
        }
        let kind = FaultKind::from_terminal(type_text);
        if kind.is_none() {
            out.push(format!("Invalid fault type {type_text}\n"));
        }
        let param = scan_f32(args[3]).unwrap_or(0.0);
        let start = scan_i32(args[4]).unwrap_or(0);
        let duration = scan_i32(args[5]).unwrap_or(0);
        let (Some(kind), true) = (kind, out.is_empty()) else {
            return out;
        };
        match self.add(id, kind, param, start, duration) {
            Ok(()) => out.push(format!(
                "Fault {type_text} with parameter {:.2} successfully added to probe {id}.\n",
                f64::from(param)
            )),
            Err(AddFaultError::NoFreeSlot) => {
                out.push("Too many faults on this probe, fault not added.\n".to_string())
            }
            Err(AddFaultError::NoFreeProbe) => {
                out.push("Too many probes in use, fault not added.\n".to_string())
            }
            Err(AddFaultError::IdTooLong) => {
                out.push(format!("Too long ID. Maximum length is {MAX_ID_LEN}\n"))
            }
        }
        out
    }

    fn cmd_print_faults(&self) -> Vec<String> {
        let mut out = vec!["Currently active faults:".to_string()];
        for probe in self.probes.iter().filter(|p| p.active) {
            for slot in probe.slots.iter().filter(|s| s.active) {
                out.push(format!(
                    "\nProbe   : {}\nIT now  : {}\nType    : {}\nParam   : {:.2}\nStart   : {}\nDuration: {}",
                    probe.id,
                    probe.iteration,
                    slot.kind,
                    f64::from(slot.param),
                    slot.start_it,
                    slot.duration
                ));
            }
        }
        out.push(" ".to_string());
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fi() -> FaultInjection {
        let mut fi = FaultInjection::default();
        fi.set_enabled(true);
        fi
    }

    fn run(fi: &mut FaultInjection, line: &str) -> Vec<String> {
        let args: Vec<&str> = line.split(' ').filter(|t| !t.is_empty()).collect();
        fi.terminal(&args).expect("an fi command")
    }

    #[test]
    fn a_fault_applies_on_calls_start_plus_one_to_start_plus_duration_after_the_add() {
        let mut fi = fi();
        for _ in 0..7 {
            fi.evaluate("uwb_range_50", 1.0);
        }
        fi.add("uwb_range_50", FaultKind::Offset, 4.0, 2, 3)
            .unwrap();
        let values: Vec<f32> = (0..8)
            .map(|_| fi.evaluate("uwb_range_50", 1.0).value)
            .collect();
        assert_eq!(values, [1.0, 1.0, 5.0, 5.0, 5.0, 1.0, 1.0, 1.0]);
    }

    #[test]
    fn duration_zero_is_permanent_negative_never_and_negative_start_at_once() {
        let mut fi = fi();
        fi.add("a", FaultKind::SetTo, 7.0, 0, 0).unwrap();
        fi.add("b", FaultKind::SetTo, 7.0, 0, -1).unwrap();
        fi.add("c", FaultKind::SetTo, 7.0, -3, 1).unwrap();
        assert!((0..100).all(|_| fi.evaluate("a", 0.0).value == 7.0));
        assert!((0..100).all(|_| fi.evaluate("b", 0.0).value == 0.0));
        // start_it = -3, iteration 0: 0 - (-3) = 3 ≥ duration 1, so it does not apply either.
        assert_eq!(fi.evaluate("c", 0.0).value, 0.0);
        let mut fi2 = self::fi();
        fi2.add("d", FaultKind::SetTo, 7.0, -1, 2).unwrap();
        assert_eq!(fi2.evaluate("d", 0.0).value, 7.0);
    }

    #[test]
    fn faults_compose_in_slot_order() {
        let mut fi = fi();
        fi.add("px", FaultKind::Offset, 1.0, 0, 0).unwrap();
        fi.add("px", FaultKind::Amplification, 3.0, 0, 0).unwrap();
        let out = fi.evaluate("px", 2.0);
        assert_eq!(out.value, 9.0);
        assert_eq!(out.applied_slots, 0b11);
        let mut fi = self::fi();
        fi.add("px", FaultKind::Amplification, 3.0, 0, 0).unwrap();
        fi.add("px", FaultKind::Offset, 1.0, 0, 0).unwrap();
        assert_eq!(fi.evaluate("px", 2.0).value, 7.0);
    }

    #[test]
    fn disabled_injection_freezes_counters_and_suspends_faults() {
        let mut fi = fi();
        fi.add("px", FaultKind::Offset, 1.0, 1, 1).unwrap();
        fi.set_enabled(false);
        for _ in 0..10 {
            assert_eq!(fi.evaluate("px", 0.0).value, 0.0);
        }
        fi.set_enabled(true);
        assert_eq!(fi.evaluate("px", 0.0).value, 0.0);
        assert_eq!(fi.evaluate("px", 0.0).value, 1.0);
        assert_eq!(fi.evaluate("px", 0.0).value, 0.0);
    }

    #[test]
    fn slots_are_never_freed_and_probes_run_out() {
        let mut fi = fi();
        for _ in 0..5 {
            run(&mut fi, "fi_add_fault px OFFSET 1 0 1");
        }
        fi.evaluate("px", 0.0);
        assert_eq!(
            run(&mut fi, "fi_add_fault px OFFSET 1 0 1"),
            ["Too many faults on this probe, fault not added.\n"]
        );
        for id in ["a", "b", "c", "d"] {
            run(&mut fi, &format!("fi_add_fault {id} NONE 0 0 0"));
        }
        assert_eq!(
            run(&mut fi, "fi_add_fault e OFFSET 1 0 1"),
            ["Too many probes in use, fault not added.\n"]
        );
        assert_eq!(run(&mut fi, "fi_clear_faults"), ["Faults cleared\n"]);
        assert_eq!(
            run(&mut fi, "fi_add_fault e OFFSET 1 0 1"),
            ["Fault OFFSET with parameter 1.00 successfully added to probe e.\n"]
        );
        // The cleared probe "px" keeps its id and is re-activated by name.
        run(&mut fi, "fi_add_fault px OFFSET 1 0 1");
        assert_eq!(fi.probes().iter().filter(|p| p.active).count(), 2);
    }

    #[test]
    fn reset_counters_shifts_pending_faults_later() {
        let mut fi = fi();
        // A probe counts only once it exists.
        fi.add("px", FaultKind::None, 0.0, 0, 0).unwrap();
        for _ in 0..10 {
            fi.evaluate("px", 0.0);
        }
        fi.add("px", FaultKind::Offset, 1.0, 2, 1).unwrap(); // start_it = 12
        assert_eq!(
            run(&mut fi, "fi_reset_cnt"),
            ["Probe iteration counters reset"]
        );
        let hits: Vec<usize> = (0..20)
            .filter(|_| fi.evaluate("px", 0.0).value == 1.0)
            .collect();
        assert_eq!(hits, [12]);
    }

    #[test]
    fn terminal_reply_texts_are_exact() {
        let mut fi = FaultInjection::default();
        assert_eq!(
            run(&mut fi, "fi_set_enabled 1"),
            ["Fault Injection enabled\n"]
        );
        assert_eq!(
            run(&mut fi, "fi_set_enabled 0"),
            ["Fault Injection disabled\n"]
        );
        assert_eq!(
            run(&mut fi, "fi_set_enabled yes"),
            ["Invalid argument yes\n"]
        );
        assert_eq!(
            run(&mut fi, "fi_set_enabled"),
            ["Wrong number of arguments\n"]
        );
        assert_eq!(
            run(&mut fi, "fi_add_fault uwb_range_50 OFFSET 2.0 15 8"),
            ["Fault OFFSET with parameter 2.00 successfully added to probe uwb_range_50.\n"]
        );
        assert_eq!(
            run(&mut fi, "fi_add_fault abcdefghijklmnopqrstu offset x 1 1"),
            [
                "Too long ID. Maximum length is 20\n",
                "Invalid fault type offset\n"
            ]
        );
        assert_eq!(
            run(&mut fi, "fi_add_fault px OFFSET 1 1"),
            ["Wrong number of arguments\n"]
        );
        assert_eq!(
            run(&mut fi, "fi_add_fault px none abc 0 0"),
            ["Fault none with parameter 0.00 successfully added to probe px.\n"]
        );
        assert_eq!(
            run(&mut fi, "fi_print_faults"),
            [
                "Currently active faults:",
                "\nProbe   : uwb_range_50\nIT now  : 0\nType    : OFFSET\nParam   : 2.00\nStart   : 15\nDuration: 8",
                "\nProbe   : px\nIT now  : 0\nType    : NONE\nParam   : 0.00\nStart   : 0\nDuration: 0",
                " "
            ]
        );
        assert!(fi.terminal(&["ping"]).is_none());
    }
}
