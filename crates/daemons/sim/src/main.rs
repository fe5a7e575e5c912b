//! `hcc-sim CONFIG [--namespace NS] [--lockstep]`: see [`hcc_sim::daemon`].

#[global_allocator]
static ALLOCATOR: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

fn main() -> std::process::ExitCode {
    hcc_sim::daemon::main_with_args(std::env::args_os())
}
