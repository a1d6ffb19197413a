//! The result of a cross-validation (`sysid validate`): the model identified on one record
//! predicting another record of the same building.

use models::description::StructureDescription;
use serde::{Deserialize, Serialize};

use super::{FreeRun, ModalComparison};
use crate::record::number;

/// The result of a cross-validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CrossValidation {
    /// The record the model was identified on, and the record it predicts.
    pub record: String,
    pub data: String,
    pub algorithm: String,
    pub seed: u64,
    pub run: u64,
    pub structure: StructureDescription,
    pub param_names: Vec<String>,
    #[serde(with = "number::vec")]
    pub theta_val: Vec<f64>,
    pub free_run: FreeRun,
    pub modal: ModalComparison,
    /// What was assumed about the other record.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}
