//! A checkpoint of the run at the current step: the master replica's weights (with their average when one is
//! kept), its optimiser, the run's state and the settings a resume is checked against.

use std::path::PathBuf;

use dggt_run::average::WeightAverage;
use dggt_run::checkpoint::Weights;
use dggt_run::run_folder;

use super::setup::Trainer;
use crate::checkpoint;
use crate::error::TrainError;
use crate::resume::ConfiguredSections;

impl Trainer {
    /// Writes a checkpoint of the master replica at the current step.
    pub(super) fn save_checkpoint(&self) -> Result<PathBuf, TrainError> {
        let run = &self.config.run;
        let master = self.replicas.master();
        let settings = checkpoint::Settings {
            model: self.model_config.clone(),
            preprocess: self.config.data.preprocess,
            configured: ConfiguredSections::of(&self.config),
        };
        let weights = match self.average.as_ref().and_then(WeightAverage::average) {
            Some(average) => Weights::Averaged { trained: &master.model, average },
            None => Weights::Trained(&master.model),
        };
        checkpoint::save(
            &run.out_dir.join(run_folder::CHECKPOINTS),
            weights,
            &settings,
            &master.optimizer,
            &self.state,
            run.keep_checkpoints,
        )
    }
}
