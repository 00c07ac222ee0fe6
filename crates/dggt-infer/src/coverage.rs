//! How much of the network a checkpoint in the release's format covers (`.pt`, `.safetensors`: the DGGT
//! release, or VGGT-1B): the top-level modules it leaves fresh, a warning when those are the scene modules
//! (the Gaussians, dynamic maps, sky and renders are then not meaningful), and a refusal when it matches
//! nothing or leaves the core without weights.

use dggt_model::weights::LoadReport;

/// Modules without which nothing can be reconstructed.
const CORE_MODULES: [&str; 3] = ["aggregator", "camera_head", "depth_head"];
/// Modules whose absence leaves the 4D outputs meaningless.
const SCENE_MODULES: [&str; 3] = ["gs_head", "instance_head", "sky_model"];

/// Why a checkpoint in the release's format cannot start the network.
#[derive(Debug, thiserror::Error)]
pub enum CoverageError {
    #[error("no tensor in it matches the network of {architecture} (not a DGGT or VGGT checkpoint?)")]
    NothingMatches { architecture: String },
    /// Modules the network cannot do without (aggregator, camera and depth heads) left without weights.
    #[error(
        "lacks weights of {modules:?} that the architecture of {architecture} needs ({missing} tensors missing, e.g. \
         {examples:?})"
    )]
    CoreMissing { modules: Vec<String>, architecture: String, missing: usize, examples: Vec<String> },
}

/// The top-level modules a release-format load left fresh; an error when it matched nothing or left the core
/// without weights, a warning when the scene modules are untrained.
pub(crate) fn check_release_coverage(
    report: &LoadReport,
    arch_name: &str,
    warnings: &mut Vec<String>,
) -> Result<Vec<String>, CoverageError> {
    if report.applied.is_empty() {
        return Err(CoverageError::NothingMatches { architecture: arch_name.to_string() });
    }
    let mut fresh: Vec<String> = report.missing.iter().map(|p| p.split('.').next().unwrap_or(p).to_string()).collect();
    fresh.sort();
    fresh.dedup();
    let missing_core: Vec<&String> = fresh.iter().filter(|m| CORE_MODULES.contains(&m.as_str())).collect();
    if !missing_core.is_empty() {
        return Err(CoverageError::CoreMissing {
            modules: missing_core.into_iter().cloned().collect(),
            architecture: arch_name.to_string(),
            missing: report.missing.len(),
            examples: report.missing.iter().take(3).cloned().collect(),
        });
    }
    let untrained: Vec<&String> = fresh.iter().filter(|m| SCENE_MODULES.contains(&m.as_str())).collect();
    if !untrained.is_empty() {
        warnings.push(format!(
            "the checkpoint has no weights for {untrained:?} (a VGGT checkpoint?): these modules are untrained, so \
             the Gaussians, dynamic maps, sky and renders are not meaningful; cameras and depth are"
        ));
    }
    if !report.unused.is_empty() {
        tracing::debug!(count = report.unused.len(), "checkpoint tensors not used by this architecture");
    }
    Ok(fresh)
}
