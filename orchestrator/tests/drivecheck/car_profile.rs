//! `--profile` end to end: a campaign on the embedded simulated car with a car profile records
//! the profile (its hash in `campaign.json` and every case, the profile itself in the recording),
//! drives another car than the default, refuses a profile with a real car or one that names an
//! anchor the scenario lacks (naming the field), and a replay on another profile warns.

use crate::common;

use common::{campaign, drivecheck, path, text};

use campaign::files::{CampaignRecord, Case};
use car_sim::CarProfile;
use recording::{Recording, SIM_PROFILE_METADATA};

/// A car whose anchor 50 stands 0.4 m from its surveyed place with a range bias, which loses
/// 15 % of its exchanges and whose odometry over-reads by 3 %.
const PROFILE: &str = r#"
format = "drivecheck-car-profile"
version = 1
[radio]
exchange_drop_rate = 0.15
[anchors."50"]
offset_m = [0.4, 0.0]
range_bias_m = -0.1
[odometry]
scale = 0.97
[imu]
yaw_bias_deg = 1.5
"#;

fn worst(dir: &std::path::Path, tests: usize) -> Vec<f64> {
    (0..tests)
        .map(|i| {
            let case = Case::from_json(
                &std::fs::read_to_string(dir.join(format!("case-{i:03}.json"))).unwrap(),
            )
            .unwrap();
            case.segments
                .iter()
                .filter_map(|s| s.oracle.stats.map(|st| st.max_m))
                .fold(0.0, f64::max)
        })
        .collect()
}

#[test]
fn a_campaign_on_a_profile_records_it_and_drives_another_car() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("car.toml");
    std::fs::write(&file, PROFILE).unwrap();
    let profiled = tmp.path().join("profiled");
    std::fs::create_dir(&profiled).unwrap();
    let run = campaign(&profiled, 3, 3, &["--profile", path(&file)], 1);
    let default = tmp.path().join("default");
    std::fs::create_dir(&default).unwrap();
    let base = campaign(&default, 3, 3, &[], 1);

    let expected = CarProfile::from_toml(PROFILE, "car.toml").unwrap().hash();
    let record =
        CampaignRecord::from_json(&std::fs::read_to_string(run.join("campaign.json")).unwrap())
            .unwrap();
    let recorded = record.car_profile.expect("the profile is recorded");
    assert_eq!(recorded.hash, expected);
    assert_eq!(recorded.name, path(&file));
    let case =
        Case::from_json(&std::fs::read_to_string(run.join("case-000.json")).unwrap()).unwrap();
    assert_eq!(case.car_profile.unwrap().hash, expected);
    let recording = Recording::read(&run.join("campaign.mcap")).unwrap();
    let meta = recording
        .metadata(SIM_PROFILE_METADATA)
        .expect("the simulator's profile is in the recording");
    assert_eq!(
        CarProfile::from_toml(&meta["toml"], "recorded")
            .unwrap()
            .hash(),
        expected
    );
    let default_record =
        CampaignRecord::from_json(&std::fs::read_to_string(base.join("campaign.json")).unwrap())
            .unwrap();
    assert_eq!(
        default_record.car_profile.unwrap().hash,
        CarProfile::default().hash(),
        "a campaign without --profile records the default car"
    );
    assert_ne!(
        worst(&run, 3),
        worst(&base, 3),
        "the profile changes the car"
    );

    // A replay of the profiled case on the default car warns; on its own profile it does not.
    let other = drivecheck(&[
        "replay",
        path(&run.join("case-000.json")),
        "--out",
        path(&tmp.path().join("replay-default")),
    ]);
    assert!(
        String::from_utf8_lossy(&other.stderr).contains("was driven on car profile"),
        "{}",
        text(&other)
    );
    let same = drivecheck(&[
        "replay",
        path(&run.join("case-000.json")),
        "--profile",
        path(&file),
        "--out",
        path(&tmp.path().join("replay-same")),
    ]);
    assert!(
        !String::from_utf8_lossy(&same.stderr).contains("was driven on car profile"),
        "{}",
        text(&same)
    );
}

#[test]
fn a_bad_profile_is_refused_naming_its_field_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        (
            "[anchors.\"57\"]\noffset_m = [0.1, 0.0]\n",
            vec![],
            "anchors.\"57\": the scenario has no anchor 57 (its anchors: 234, 50)",
        ),
        (
            "[radio]\nexchange_drop_rate = 1.5\n",
            vec![],
            "radio.exchange_drop_rate: 1.5 is not a share",
        ),
        (
            "[gnss]\nsigma = 0.1\n",
            vec![],
            "car.toml:4:1: gnss.sigma: unknown field `sigma`",
        ),
        (
            "",
            vec!["--car", "tcp://127.0.0.1:9"],
            "--profile describes the embedded simulated car (--car sim)",
        ),
    ];
    for (body, extra, expected) in cases {
        let file = tmp.path().join("car.toml");
        std::fs::write(
            &file,
            format!("format = \"drivecheck-car-profile\"\nversion = 1\n{body}"),
        )
        .unwrap();
        let out_dir = tmp.path().join("never");
        let mut args = vec!["run", "--tests", "1", "--profile", path(&file)];
        args.extend(extra.iter().copied());
        args.extend(["--out", path(&out_dir)]);
        let out = drivecheck(&args);
        assert_eq!(out.status.code(), Some(2), "{}", text(&out));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains(expected), "{stderr}\nexpected: {expected}");
        assert!(!out_dir.exists(), "an error leaves no run directory");
    }
}

/// A car whose two anchors stand 0.3–0.4 m from their surveyed places with range biases, as
/// real anchors do.
const SURVEY_ERRORS: &str = r#"
format = "drivecheck-car-profile"
version = 1
[radio]
exchange_drop_rate = 0.10
[anchors."50"]
offset_m = [0.35, -0.2]
range_bias_m = 0.12
[anchors."234"]
offset_m = [-0.25, 0.3]
range_bias_m = -0.08
[odometry]
scale = 1.025
[imu]
yaw_bias_deg = 1.2
"#;

#[test]
fn twin_check_tells_the_right_profile_from_the_default_car_and_the_report_shows_it() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("car.toml");
    std::fs::write(&file, SURVEY_ERRORS).unwrap();
    // The "car": the embedded simulator with the profile.
    let run = campaign(tmp.path(), 11, 8, &["--profile", path(&file)], 1);
    let out = drivecheck(&[
        "twin",
        "check",
        path(&run),
        "--profile",
        path(&file),
        "--runs",
        "2",
        "--repeat",
        path(&run),
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let printed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(printed["command"], "twin check", "{printed:#}");
    let printed = campaign::files::TwinCheck::from_json(&printed["twin"].to_string()).unwrap();
    let written = campaign::files::TwinCheck::from_json(
        &std::fs::read_to_string(run.join("twin.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(printed, written);
    assert_eq!(written.cases, 8);
    let [own, default] = &written.profiles[..] else {
        panic!("the profile and the default car: {:?}", written.profiles);
    };
    assert_eq!(default.profile.name, "default");
    let (own, default) = (own.summary, default.summary);
    assert!(own.segments > 10, "{own:?}");
    assert!(
        own.median_abs_delta_m.unwrap() < default.median_abs_delta_m.unwrap() / 2.0,
        "the right profile reproduces the car far better: {own:?} vs {default:?}"
    );
    assert!(own.verdicts_agreed.unwrap() >= default.verdicts_agreed.unwrap());
    let repeat = written.repeatability.expect("--repeat").summary;
    assert_eq!(
        repeat.verdicts_agreed,
        Some(1.0),
        "a run agrees with itself"
    );
    assert_eq!(repeat.median_abs_delta_m, Some(0.0));

    let report = drivecheck(&["report", path(&run)]);
    assert_eq!(report.status.code(), Some(0), "{}", text(&report));
    let html = std::fs::read_to_string(run.join("report.html")).unwrap();
    assert!(
        html.contains("<section id=\"twin\">"),
        "the report shows the twin check"
    );
    assert!(html.contains("car profile default"));
}
