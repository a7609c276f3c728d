//! Switch plans (`.symframe-staging-*/.ready`), which anyone who can write into an output
//! folder can plant: parsed and checked as the next job's recovery does, with the token the
//! plan itself claims (so mutated plans reach the checksum and name checks).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let token = serde_json::from_str::<serde_json::Value>(text)
        .ok()
        .and_then(|v| v["token"].as_str().and_then(|t| u64::from_str_radix(t, 16).ok()))
        .unwrap_or(1);
    let _ = symframe_job::check_switch_plan(text, token);
});
