fn main() {
    std::process::exit(radiosity::cli::main());
}
