use super::common::Global;

#[derive(clap::Args, Debug)]
pub struct InspectArgs {}

pub fn run(_a: &InspectArgs, _g: &Global) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
