//! Every role's run-file parser and check on arbitrary text: a bad run file is an error naming
//! what is wrong, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use run::RoleConfig;

fn check<C: RoleConfig>(text: &str) {
    if let Ok(config) = C::parse(text) {
        let _ = config.validate();
    }
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    check::<replay_server::ReplayServerConfig>(text);
    check::<param_server::ParamServerConfig>(text);
    check::<learner::LearnerConfig>(text);
    check::<executor::ExecutorConfig>(text);
});
