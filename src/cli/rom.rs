use super::common::Global;

#[derive(clap::Args, Debug)]
pub struct RomArgs {}

pub fn run(_a: &RomArgs, _g: &Global) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
