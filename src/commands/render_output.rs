//! What the commands that render a reconstructed scene into a folder (`dggt reconstruct`, `dggt edit`) share on
//! the command line: the device, the output folder with its `--overwrite` and `--max-output-gb`, and the
//! optional refinement of the renders (`--refine ...`).

use crate::backend::DeviceList;
use crate::commands::output::{OutputBoundArg, OutputFolderArgs};
use crate::commands::refine::RefineArgs;

/// The device, the output folder and its bound, and the refiner of a command that renders into a folder.
#[derive(Debug, Clone, clap::Args)]
pub struct RenderOutputArgs {
    /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
    #[arg(long, default_value = "cpu")]
    pub device: DeviceList,
    #[command(flatten)]
    pub folder: OutputFolderArgs,
    #[command(flatten)]
    pub bound: OutputBoundArg,
    #[command(flatten)]
    pub refine: RefineArgs,
}
