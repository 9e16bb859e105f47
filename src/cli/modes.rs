use super::common::Global;

#[derive(clap::Args, Debug)]
pub struct ModesArgs {}

pub fn run(_a: &ModesArgs, _g: &Global) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
