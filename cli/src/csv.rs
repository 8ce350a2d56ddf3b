//! Just enough CSV for numeric tables: comma-separated numbers, an optional header row, `#` comments.

use std::path::Path;

use anyhow::{Context, Result, bail};

/// Reads a numeric CSV file into rows. A first row that does not parse as numbers is taken as a
/// header and skipped; blank lines and lines starting with `#` are ignored. Every row must have the
/// same number of columns.
pub fn read_rows(path: &Path) -> Result<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse_rows(&text).with_context(|| format!("in {}", path.display()))
}

/// [`read_rows`] on text.
pub fn parse_rows(text: &str) -> Result<Vec<Vec<f64>>> {
    let mut rows: Vec<Vec<f64>> = Vec::new();
    let mut seen_first = false;
    for (number, line) in text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())) {
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let parsed: Result<Vec<f64>, _> = line.split(',').map(|f| f.trim().parse::<f64>()).collect();
        let first = !seen_first;
        seen_first = true;
        let row = match parsed {
            Ok(row) => row,
            Err(_) if first => continue, // the header
            Err(e) => bail!("line {number}: {e}: {line:?}"),
        };
        if let Some(previous) = rows.first()
            && previous.len() != row.len()
        {
            bail!("line {number} has {} columns, earlier rows have {}", row.len(), previous.len());
        }
        rows.push(row);
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_comments_and_blank_lines_are_skipped() {
        let rows = parse_rows("a0,a1\n# note\n0.5, -1\n\n1e-3,2\n").unwrap();
        assert_eq!(rows, vec![vec![0.5, -1.0], vec![1e-3, 2.0]]);
    }

    #[test]
    fn ragged_rows_and_bad_numbers_after_the_first_row_are_errors() {
        assert!(parse_rows("1,2\n3\n").is_err());
        assert!(parse_rows("1,2\n3,x\n").is_err());
    }
}
