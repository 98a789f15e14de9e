//! `rip-rt`: the 100 Hz control loop over serial, the identification experiment and the device
//! emulator. The program is [`rip_rt::cli::run`]; `rip-rt --help` describes it.

use std::process::ExitCode;

fn main() -> ExitCode {
    ExitCode::from(rip_rt::cli::run(std::env::args_os()))
}
