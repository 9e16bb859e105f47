fn main() {
    std::process::exit(rfmlab_cli::run());
}
#[path = "cli/mod.rs"]
mod rfmlab_cli;
