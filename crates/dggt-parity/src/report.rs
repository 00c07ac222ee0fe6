//! The outcome of a parity run, one row per reference output, shared by every harness.
//!
//! The pass rule is strict: a report passes only when it has rows and every one of them is [`Status::Pass`].
//! A reference output the port never compared (a name it does not know, a value it could not produce, a shape
//! it does not match) is a failure like one out of tolerance, and its status says which.

use std::fmt;

/// How one reference output fared.
#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    /// Compared and within tolerance.
    Pass,
    /// Compared, and the largest difference is beyond the tolerance.
    OutOfTolerance,
    /// Compared, and the port's values are not finite where the reference's are.
    NotFinite,
    /// Not compared: the port's value has this other shape.
    ShapeMismatch(Vec<usize>),
    /// Not compared: a name the harness has no rule for reproducing.
    Unknown,
    /// Not compared: the port did not produce the value, for this reason.
    NotProduced(String),
}

impl Status {
    pub fn is_pass(&self) -> bool {
        *self == Status::Pass
    }

    /// Whether the output was compared at all (passing or not).
    pub fn was_compared(&self) -> bool {
        matches!(self, Status::Pass | Status::OutOfTolerance | Status::NotFinite)
    }
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Status::Pass => f.pad("pass"),
            Status::OutOfTolerance => f.pad("FAIL (out of tolerance)"),
            Status::NotFinite => f.pad("FAIL (the port's values are not finite)"),
            Status::ShapeMismatch(shape) => f.pad(&format!("FAIL (not compared: the port's shape is {shape:?})")),
            Status::Unknown => f.pad("FAIL (not compared: not an output this port knows)"),
            Status::NotProduced(reason) => f.pad(&format!("FAIL (not compared: {reason})")),
        }
    }
}

/// One reference output and how the port's value compares with it.
#[derive(Debug, Clone, PartialEq)]
pub struct ParityRow {
    pub name: String,
    /// The reference's shape.
    pub shape: Vec<usize>,
    /// Largest absolute difference over the compared elements; `None` when nothing was compared.
    pub max_abs: Option<f64>,
    /// `max_abs` relative to the largest compared reference magnitude.
    pub max_rel: Option<f64>,
    /// The largest `max_abs` that passes.
    pub tolerance: Option<f64>,
    pub status: Status,
    /// How the output was compared when not elementwise.
    pub note: Option<String>,
}

impl ParityRow {
    /// A row of an output that was not compared.
    pub fn not_compared(name: &str, shape: &[usize], status: Status) -> Self {
        Self {
            name: name.to_string(),
            shape: shape.to_vec(),
            max_abs: None,
            max_rel: None,
            tolerance: None,
            status,
            note: None,
        }
    }
}

/// Every reference output of one run, in the order compared.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ParityReport {
    pub rows: Vec<ParityRow>,
}

impl ParityReport {
    /// Every reference output was compared and is within tolerance (and there was at least one).
    pub fn passed(&self) -> bool {
        !self.rows.is_empty() && self.rows.iter().all(|row| row.status.is_pass())
    }

    /// The rows that are not a pass, compared or not.
    pub fn failed(&self) -> impl Iterator<Item = &ParityRow> {
        self.rows.iter().filter(|row| !row.status.is_pass())
    }

    pub fn row(&self, name: &str) -> Option<&ParityRow> {
        self.rows.iter().find(|row| row.name == name)
    }

    /// One line: how many outputs passed and failed, and how many of the failures were never compared.
    pub fn summary(&self) -> String {
        let failed = self.failed().count();
        let not_compared = self.failed().filter(|row| !row.status.was_compared()).count();
        format!(
            "{} outputs: {} pass, {failed} fail, {not_compared} of them not compared",
            self.rows.len(),
            self.rows.len() - failed
        )
    }
}

impl fmt::Display for ParityReport {
    /// The table: name, shape, max abs difference, max relative difference, tolerance, status (and note).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let shapes: Vec<String> = self.rows.iter().map(|row| format!("{:?}", row.shape)).collect();
        let name_width = self.rows.iter().map(|row| row.name.len()).chain([6]).max().unwrap_or(6);
        let shape_width = shapes.iter().map(String::len).chain([5]).max().unwrap_or(5);
        let number = |value: Option<f64>| value.map_or_else(|| "-".to_string(), |v| format!("{v:.3e}"));
        writeln!(
            f,
            "{:<name_width$}  {:<shape_width$}  {:>11}  {:>11}  {:>11}  status",
            "output", "shape", "max abs err", "max rel err", "tolerance"
        )?;
        for (row, shape) in self.rows.iter().zip(&shapes) {
            write!(
                f,
                "{:<name_width$}  {shape:<shape_width$}  {:>11}  {:>11}  {:>11}  {}",
                row.name,
                number(row.max_abs),
                number(row.max_rel),
                number(row.tolerance),
                row.status
            )?;
            match &row.note {
                Some(note) => writeln!(f, "  ({note})")?,
                None => writeln!(f)?,
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, status: Status) -> ParityRow {
        ParityRow {
            name: name.into(),
            shape: vec![2],
            max_abs: Some(2e-5),
            max_rel: Some(1e-5),
            tolerance: Some(2e-4),
            status,
            note: None,
        }
    }

    #[test]
    fn passes_only_when_every_row_passes() {
        let passing = ParityReport { rows: vec![row("depth", Status::Pass), row("pose_enc", Status::Pass)] };
        assert!(passing.passed());
        assert_eq!(passing.summary(), "2 outputs: 2 pass, 0 fail, 0 of them not compared");
        for failing in [
            Status::OutOfTolerance,
            Status::NotFinite,
            Status::ShapeMismatch(vec![3]),
            Status::Unknown,
            Status::NotProduced("the network has no gs_head".into()),
        ] {
            let mut report = passing.clone();
            report.rows[1].status = failing.clone();
            assert!(!report.passed(), "{failing:?} must fail the report");
            assert_eq!(report.failed().map(|row| row.name.as_str()).collect::<Vec<_>>(), ["pose_enc"]);
        }
        assert!(!ParityReport::default().passed(), "a report that compared nothing does not pass");
    }

    #[test]
    fn an_output_never_compared_fails_the_report() {
        let report = ParityReport {
            rows: vec![row("depth", Status::Pass), ParityRow::not_compared("track.coords", &[2], Status::Unknown)],
        };
        assert!(!report.passed());
        assert_eq!(report.summary(), "2 outputs: 1 pass, 1 fail, 1 of them not compared");
        let table = report.to_string();
        assert!(table.lines().nth(1).unwrap().starts_with("depth") && table.contains("2.000e-5"), "{table}");
        let unknown = table.lines().find(|line| line.starts_with("track.coords")).unwrap();
        assert!(unknown.contains("FAIL (not compared: not an output this port knows)"), "{table}");
    }
}
