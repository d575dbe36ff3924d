//! Did-you-mean and word lists for error messages: the closest key or section to a misspelt
//! one (edit distance), and `a, b or c` / `a, b and c`. Shared with the station file.

use std::fmt;

/// Optimal-string-alignment distance (Levenshtein plus adjacent transpositions), ASCII
/// case-insensitive.
fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().map(|c| c.to_ascii_lowercase()).collect();
    let b: Vec<char> = b.chars().map(|c| c.to_ascii_lowercase()).collect();
    let w = b.len() + 1;
    let mut d = vec![0usize; (a.len() + 1) * w];
    for (i, row) in d.chunks_mut(w).enumerate() {
        if let Some(first) = row.first_mut() {
            *first = i;
        }
    }
    for (j, cell) in d.iter_mut().take(w).enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut best = (d[(i - 1) * w + j] + 1)
                .min(d[i * w + j - 1] + 1)
                .min(d[(i - 1) * w + j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(d[(i - 2) * w + j - 2] + 1);
            }
            d[i * w + j] = best;
        }
    }
    d[a.len() * w + b.len()]
}

/// The candidate closest to `name`, when it is close enough to be a likely misspelling (a
/// small edit distance, or one is a prefix of the other).
pub(crate) fn closest<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    let lower = name.to_ascii_lowercase();
    candidates
        .into_iter()
        .filter_map(|c| {
            let d = edit_distance(name, c);
            let prefix = lower.len() >= 3 && (c.starts_with(&lower) || lower.starts_with(c));
            let close = d <= 1 || d * 3 <= name.chars().count().max(c.len());
            (close || prefix).then_some((d, c))
        })
        .min_by_key(|&(d, _)| d)
        .map(|(_, c)| c)
}

/// `a, b or c`.
pub(crate) fn or_list<T: fmt::Display>(items: &[T]) -> String {
    word_list(items, "or")
}

/// `a, b and c`.
pub(crate) fn and_list<T: fmt::Display>(items: &[T]) -> String {
    word_list(items, "and")
}

fn word_list<T: fmt::Display>(items: &[T], conjunction: &str) -> String {
    let words: Vec<String> = items.iter().map(ToString::to_string).collect();
    match words.split_last() {
        None => String::new(),
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} {conjunction} {last}", rest.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misspellings_find_their_key() {
        assert_eq!(
            closest("tabel", ["plan", "table", "dmm", "simulation"]),
            Some("table")
        );
        assert_eq!(
            closest("sim", ["plan", "table", "dmm", "simulation"]),
            Some("simulation")
        );
        assert_eq!(
            closest("rate_dps", ["rates_dps", "settle_s"]),
            Some("rates_dps")
        );
        assert_eq!(
            closest("colour", ["plan", "table", "dmm", "simulation"]),
            None
        );
        assert_eq!(edit_distance("tabel", "table"), 1);
        assert_eq!(edit_distance("", "dmm"), 3);
    }
}
