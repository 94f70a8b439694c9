//! Prints gms-core's self-test hashes on the host (`cargo target-bench` compares them with
//! the emulated Cortex-M4F's).
fn main() {
    println!(
        "equiv friction {}",
        gms_core::selftest::friction_hash(20_000)
    );
    println!(
        "equiv controller {}",
        gms_core::selftest::controller_hash(5_000)
    );
}
