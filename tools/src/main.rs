//! `hils`: host tools of the railway brake HILS. See README.md.

use clap::Parser;

/// A user error is printed as its message and causes (`error: ...: ...`), exit code 1:
/// never with a backtrace, whatever `RUST_BACKTRACE` says (anyhow captures one when it is
/// set, and `main` returning the error would print it).
fn main() -> std::process::ExitCode {
    let result = host_cpu_check().and_then(|()| hils::cli::run(hils::cli::Cli::parse()));
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// A build for x86-64-v3 (`.cargo/config.toml`) on a CPU without AVX2/FMA would stop with
/// an illegal instruction somewhere later: say so plainly instead, with the way out.
fn host_cpu_check() -> anyhow::Result<()> {
    #[cfg(all(
        target_arch = "x86_64",
        target_feature = "avx2",
        target_feature = "fma"
    ))]
    if !(std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma"))
    {
        anyhow::bail!(
            "this hils was built for x86-64-v3 (AVX2, FMA; .cargo/config.toml) but this CPU \
             lacks them: rebuild with RUSTFLAGS=\"-C target-cpu=x86-64\" cargo build --release -p hils"
        );
    }
    Ok(())
}
