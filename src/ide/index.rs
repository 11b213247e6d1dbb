//! Byte offsets to editor positions (zero-based lines, UTF-16 columns, as LSP counts) and
//! back.

/// Line starts of a text.
#[derive(Debug, Clone)]
pub struct LineIndex<'a> {
    text: &'a str,
    starts: Vec<usize>,
}

impl<'a> LineIndex<'a> {
    /// Indexes `text`.
    pub fn new(text: &'a str) -> Self {
        let mut starts = vec![0];
        starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        LineIndex { text, starts }
    }

    /// Line and UTF-16 column of a byte offset.
    pub fn position(&self, offset: usize) -> (u32, u32) {
        let offset = offset.min(self.text.len());
        let line = self.starts.partition_point(|&s| s <= offset) - 1;
        let start = self.starts[line];
        let prefix = self.text.get(start..offset).unwrap_or_default();
        (line as u32, prefix.encode_utf16().count() as u32)
    }

    /// Byte offset of a line and UTF-16 column (clamped to the text).
    pub fn offset(&self, line: u32, column: u32) -> usize {
        let Some(&start) = self.starts.get(line as usize) else {
            return self.text.len();
        };
        let end = self
            .starts
            .get(line as usize + 1)
            .copied()
            .unwrap_or(self.text.len());
        let mut units = 0;
        for (index, c) in self.text[start..end].char_indices() {
            if units >= column as usize {
                return start + index;
            }
            units += c.len_utf16();
        }
        end
    }
}
