//! "Did you mean" suggestions by edit distance, shared by the checks, the data reader and
//! the input programs.

/// The candidate closest to `name` by edit distance, if it is close enough to be a likely
/// typo: a candidate equal to `name` ignoring case is the best match; otherwise a
/// single-character name gets no suggestion, and longer names allow one edit or a third of
/// their length, whichever is more. Ties go to the candidate of the most similar length
/// (`SO` suggests `S0`, not `S`).
pub fn closest<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let length = name.chars().count();
    let budget = if length <= 1 { 0 } else { (length / 3).max(1) };
    candidates
        .into_iter()
        .filter(|candidate| *candidate != name)
        .map(|candidate| {
            let distance = if candidate.eq_ignore_ascii_case(name) {
                0
            } else {
                edit_distance(name, candidate)
            };
            (
                distance,
                candidate.chars().count().abs_diff(length),
                candidate,
            )
        })
        .filter(|&(distance, _, _)| distance <= budget)
        .min()
        .map(|(_, _, candidate)| candidate)
}

/// A help line: "did you mean `x`?" when a close candidate exists, then the full list.
pub fn did_you_mean(name: &str, candidates: &[&str], what: &str) -> String {
    let listed = candidates
        .iter()
        .map(|c| format!("`{c}`"))
        .collect::<Vec<_>>()
        .join(", ");
    match closest(name, candidates.iter().copied()) {
        Some(close) => format!("did you mean `{close}`? {what}: {listed}"),
        None => format!("{what}: {listed}"),
    }
}

/// Edit distance between `a` and `b` in characters: insertions, deletions, substitutions
/// and transpositions of two neighbours each count one (optimal string alignment).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let width = b.len() + 1;
    // table[i * width + j]: distance between the first i chars of a and the first j of b.
    let mut table: Vec<usize> = vec![0; (a.len() + 1) * width];
    for (j, cell) in table.iter_mut().take(width).enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        table[i * width] = i;
        for j in 1..=b.len() {
            let substitution = table[(i - 1) * width + j - 1] + usize::from(a[i - 1] != b[j - 1]);
            let deletion = table[(i - 1) * width + j] + 1;
            let insertion = table[i * width + j - 1] + 1;
            let mut best = substitution.min(deletion).min(insertion);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(table[(i - 2) * width + j - 2] + 1);
            }
            table[i * width + j] = best;
        }
    }
    table[a.len() * width + b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edit_distance_counts_insertions_deletions_and_substitutions() {
        assert_eq!(edit_distance("", ""), 0);
        assert_eq!(edit_distance("abc", ""), 3);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("flaw", "lawn"), 2);
        assert_eq!(edit_distance("E0", "E_0"), 1);
        assert_eq!(edit_distance("chrip", "chirp"), 1);
        assert_eq!(edit_distance("ab", "ba"), 1);
    }

    #[test]
    fn closest_suggests_only_near_misses() {
        assert_eq!(closest("Xx", ["X", "A", "S"]), Some("X"));
        assert_eq!(closest("s", ["X", "S"]), Some("S"));
        assert_eq!(closest("substrate", ["u", "X"]), None);
        assert_eq!(closest("v", ["u", "X"]), None);
        assert_eq!(
            closest("chrip", ["steps", "const", "chirp", "csv"]),
            Some("chirp")
        );
    }

    #[test]
    fn did_you_mean_lists_every_candidate() {
        let help = did_you_mean("Sx", &["t", "S"], "columns present");
        assert_eq!(help, "did you mean `S`? columns present: `t`, `S`");
        let help = did_you_mean("zzz", &["t", "S"], "columns present");
        assert_eq!(help, "columns present: `t`, `S`");
    }
}
