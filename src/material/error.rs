//! Errors of the constitutive-model layer.

/// What can go wrong when choosing a constitutive model or checking its parameters.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MaterialError {
    /// The model name is not one of [`super::MODEL_NAMES`].
    #[error("unknown constitutive model '{name}': valid names are {valid}")]
    UnknownModel { name: String, valid: String },
    /// `generalized_maxwell` was asked for without a number of branches.
    #[error(
        "model 'generalized_maxwell' needs a number of Maxwell branches (n_branches >= 1, e.g. 3)"
    )]
    MissingBranches,
    /// A number of branches was given for a model that has none, or 0 branches were asked for.
    #[error("n_branches = {n} is not valid for model '{model}': {hint}")]
    BadBranches {
        model: String,
        n: usize,
        hint: String,
    },
    /// The parameter vector has the wrong length.
    #[error("model '{model}' takes {expected} parameters ({names}), got {got}")]
    WrongParamCount {
        model: String,
        expected: usize,
        got: usize,
        names: String,
    },
    /// A parameter lies outside its admissible open interval (or is not finite).
    #[error("parameter {param} of model '{model}' = {value:e} {unit} is outside its admissible range ({lo:e}, {hi:e}); choose a value inside it")]
    OutOfBounds {
        model: String,
        param: String,
        value: f64,
        unit: String,
        lo: f64,
        hi: f64,
    },
    /// The paper's Table 4 has only Models 1-5.
    #[error("the paper's Table 4 has Models 1 to 5, not Model {0}")]
    NoSuchTableModel(usize),
}
