use super::common::Global;

#[derive(clap::Args, Debug)]
pub struct SimulateArgs {}

pub fn run(_a: &SimulateArgs, _g: &Global) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
