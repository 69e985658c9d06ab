//! The trajectory generator's configuration as a scenario describes it.

use scenarios::GeneratorSettings;
use trajgen::{GeneratorConfig, Strategy};

/// The generator configuration for a scenario's settings and a chosen strategy.
pub fn generator_config(settings: &GeneratorSettings, strategy: Strategy) -> GeneratorConfig {
    let mut config = GeneratorConfig::default()
        .with_constraints(settings.constraints())
        .with_ahead_margin(settings.ahead_margin)
        .with_strategy(strategy);
    config.inner_tries = u32::try_from(settings.inner_tries).unwrap_or(u32::MAX);
    config.outer_tries = u32::try_from(settings.outer_tries).unwrap_or(u32::MAX);
    config
}
