//! The real check: an iceoryx2 publish-subscribe round trip per cycle
//! (`loan_uninit` → write → `send` → `receive`), as the controller's torque
//! loop does it, with `RtAllocator` installed as this test binary's global
//! allocator.
//!
//! iceoryx2 0.10 allocates a small reference-counted state per loan; on a
//! real-time thread that allocation must come from the pool, never from the
//! system allocator, and the loop must take no page faults.

use std::error::Error;
use std::hint::black_box;

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use hcc_rtalloc::{
    RtAllocator, RtSection, page_faults, prefault, prefault_stack, stats, thread_stats,
};

#[global_allocator]
static ALLOCATOR: RtAllocator = RtAllocator::new();

const CYCLES: u64 = 10_000;
const WARM_UP: u64 = 1_000;

type Payload = [u64; 8];

/// Pool occupancy seen inside one cycle (while the loan is held) and after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Occupancy {
    during: u64,
    after: u64,
}

/// One round trip. Returns the occupancy and a checksum of the received sample.
#[inline(never)]
fn cycle(
    publisher: &Publisher<ipc::Service, Payload, ()>,
    subscriber: &Subscriber<ipc::Service, Payload, ()>,
    i: u64,
) -> Result<(Occupancy, u64), Box<dyn Error>> {
    let sample = publisher.loan_uninit()?;
    let during = stats().pool_in_use;
    let sample = sample.write_payload([i; 8]);
    sample.send()?;
    let received = subscriber
        .receive()?
        .ok_or("no sample received after send")?;
    let value = received.payload()[7];
    drop(received);
    let after = stats().pool_in_use;
    Ok((Occupancy { during, after }, value))
}

#[test]
fn publish_receive_loop_on_rt_thread_uses_only_the_pool() -> Result<(), Box<dyn Error>> {
    let node = NodeBuilder::new().create::<ipc::Service>()?;
    let name = format!("hcc/rtalloc-test/{}/round-trip", std::process::id());
    let service = node
        .service_builder(&name.as_str().try_into()?)
        .publish_subscribe::<Payload>()
        .create()?;
    let publisher = service.publisher_builder().create()?;
    let subscriber = service.subscriber_builder().create()?;

    // Without the pool (thread not real-time): every call goes to System.
    for i in 0..WARM_UP {
        cycle(&publisher, &subscriber, i)?;
    }
    let before = thread_stats();
    for i in 0..CYCLES {
        let (_, value) = cycle(&publisher, &subscriber, i)?;
        if value != i {
            return Err(format!("cycle {i}: received {value}").into());
        }
    }
    let system_only = thread_stats().since(before);
    let allocs_per_cycle = system_only.allocs as f64 / CYCLES as f64;
    println!(
        "iceoryx2 round trip without the pool: {allocs_per_cycle} allocations/cycle \
         ({} allocs, {} frees over {CYCLES} cycles)",
        system_only.allocs, system_only.frees
    );
    assert_eq!(system_only.pool_allocs, 0);
    assert!(
        system_only.allocs >= CYCLES,
        "iceoryx2 0.10 allocates per loan; if this fails the workaround may be obsolete"
    );

    // With the pool, memory locked as the daemons do it (when permitted).
    let locked = hcc_rtalloc::lock_memory()
        .map_err(|e| println!("{e}: major page faults cannot be ruled out"))
        .is_ok();
    prefault();
    prefault_stack(256 * 1024)?;
    let rt = RtSection::enter();
    for i in 0..WARM_UP {
        cycle(&publisher, &subscriber, i)?;
    }
    hcc_rtalloc::reset_high_water();
    let baseline = stats();
    let before = thread_stats();
    let faults_before = page_faults()?;
    let first = cycle(&publisher, &subscriber, 0)?.0;
    let mut varying = 0u64;
    let mut wrong = 0u64;
    for i in 1..CYCLES {
        let (occupancy, value) = cycle(&publisher, &subscriber, i)?;
        varying += u64::from(occupancy != first);
        wrong += u64::from(value != i);
    }
    let faults = page_faults()?.since(faults_before);
    drop(rt);
    let pooled = thread_stats().since(before);
    let after = stats();
    black_box(&publisher);

    println!(
        "iceoryx2 round trip with the pool: {} pool allocs/cycle, {} system allocs, \
         {} fallbacks, occupancy {} during / {} after each cycle, high-water {} \
         (baseline {}), page faults {faults:?}",
        pooled.pool_allocs as f64 / CYCLES as f64,
        pooled.system_allocs,
        pooled.fallbacks,
        first.during,
        first.after,
        after.pool_high_water,
        baseline.pool_in_use,
    );
    assert_eq!(wrong, 0);
    assert_eq!(pooled.system_allocs, 0, "{pooled:?}");
    assert_eq!(pooled.system_frees, 0, "{pooled:?}");
    assert_eq!(pooled.fallbacks, 0, "{pooled:?}");
    assert_eq!(after.rt_system_allocs, baseline.rt_system_allocs);
    assert_eq!(after.rt_fallbacks, baseline.rt_fallbacks);
    assert_eq!(
        pooled.pool_allocs, system_only.allocs,
        "same calls, now pooled"
    );
    assert_eq!(varying, 0, "occupancy constant from cycle to cycle");
    assert_eq!(first.after, baseline.pool_in_use);
    assert!(
        first.during > first.after,
        "the loan's state is a pool block"
    );
    assert_eq!(after.pool_high_water, first.during);
    assert_eq!(after.pool_in_use, baseline.pool_in_use);
    assert_eq!(
        faults.unexpected(locked),
        0,
        "{faults:?}, memory locked: {locked}"
    );
    Ok(())
}
