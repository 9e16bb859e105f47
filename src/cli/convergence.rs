use super::common::Global;

#[derive(clap::Args, Debug)]
pub struct ConvergenceArgs {}

pub fn run(_a: &ConvergenceArgs, _g: &Global) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
