//! Placeholder.

use anyhow::Result;

use super::Ctx;

/// Not implemented yet.
pub fn run(_ctx: &Ctx) -> Result<String> {
    Ok(String::new())
}
