//! The `drivecheck` command.

fn main() {
    println!("drivecheck");
}
