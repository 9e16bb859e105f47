use super::common::Global;

#[derive(clap::Args, Debug)]
pub struct FrfArgs {}
#[derive(clap::Args, Debug)]
pub struct ExportMmArgs {}

pub fn run(_a: &FrfArgs, _g: &Global) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
pub fn run_export(_a: &ExportMmArgs, _g: &Global) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet")
}
