//! `hcc-controller CONFIG [--namespace NS]`: see [`hcc_controller::daemon`].

#[global_allocator]
static ALLOCATOR: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

fn main() -> std::process::ExitCode {
    hcc_controller::daemon::main_with_args(std::env::args_os())
}
