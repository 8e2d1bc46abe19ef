//! The one error type of the core; `python/mod.rs` maps it to Python exceptions in one place.
use std::fmt;

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CoreError {
    /// Input that is malformed (shape, range, NaN): becomes `ValueError`.
    InvalidInput(String),
    /// The sparsity pattern admits no assignment covering the smaller side: becomes `ValueError`.
    Infeasible {
        uncovered: usize,
        side: &'static str,
    },
    /// A sparse cost stores one entry twice: becomes `DuplicateEntries`, a `ValueError` on which
    /// the Python wrapper sums the duplicates (scipy's convention) and solves again.
    Duplicate { row: usize, col: u32 },
    /// An allocation sized by the input that the machine cannot hold (more than its physical
    /// memory, or refused by the allocator): becomes `MemoryError`. `bytes` is `None` when the
    /// size overflows `usize`.
    OutOfMemory { what: String, bytes: Option<usize> },
}

impl fmt::Display for CoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CoreError::InvalidInput(msg) => f.write_str(msg),
            CoreError::Infeasible { uncovered, side } => write!(
                f,
                "no full assignment exists within the sparsity pattern: {uncovered} {side} cannot \
                 be covered by any one-to-one assignment (add allowed pairs, e.g. each row's \
                 current match, so every {side_one} has a partner)",
                side_one = side.trim_end_matches('s')
            ),
            CoreError::Duplicate { row, col } => write!(
                f,
                "cost: row {row} stores column {col} more than once; call sum_duplicates() first"
            ),
            CoreError::OutOfMemory { what, bytes } => {
                let size = match bytes {
                    Some(b) => format!("{:.1} GiB", *b as f64 / (1u64 << 30) as f64),
                    None => "more than the address space".to_string(),
                };
                write!(
                    f,
                    "not enough memory for {what} ({size}); check the sizes passed in"
                )
            }
        }
    }
}

impl std::error::Error for CoreError {}

pub type Result<T> = std::result::Result<T, CoreError>;

pub(crate) fn invalid<T>(msg: impl Into<String>) -> Result<T> {
    Err(CoreError::InvalidInput(msg.into()))
}

pub(crate) fn out_of_memory<T>(what: &str, bytes: Option<usize>) -> Result<T> {
    Err(CoreError::OutOfMemory {
        what: what.to_string(),
        bytes,
    })
}
