fn main() {
    eprintln!("hcc-controller: not yet implemented");
    std::process::exit(2);
}
