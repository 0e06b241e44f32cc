//! Positions as editors count them: a zero-based line (lines end at LF,
//! CRLF or a lone CR, as the Language Server Protocol says) and a
//! zero-based column in UTF-16 code units; conversion to and from byte
//! offsets of the document's UTF-8 text.

/// A position in a document: line and UTF-16 column, both from zero.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Position {
    /// The line.
    pub line: u32,
    /// The column, in UTF-16 code units.
    pub character: u32,
}

/// Why a position does not name a place in the document.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PositionError {
    /// The line is past the document's last line.
    LineOutOfRange {
        /// The line asked for.
        line: u32,
        /// How many lines the document has.
        lines: usize,
    },
    /// The column falls between the two UTF-16 units of one character.
    InsideCharacter {
        /// The line.
        line: u32,
        /// The column asked for.
        character: u32,
    },
}

impl std::fmt::Display for PositionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PositionError::LineOutOfRange { line, lines } => {
                write!(f, "line {line} is past the document's {lines} lines")
            }
            PositionError::InsideCharacter { line, character } => write!(
                f,
                "column {character} of line {line} falls inside a character (between its two UTF-16 units)"
            ),
        }
    }
}

/// The start of every line of one text, for converting offsets.
#[derive(Clone, Debug)]
pub struct LineIndex {
    /// Byte offset of each line's first character (the first is 0).
    starts: Vec<usize>,
    /// Byte offset of each line's end, before its line break.
    ends: Vec<usize>,
}

impl LineIndex {
    /// Index `text`.
    pub fn new(text: &str) -> LineIndex {
        let bytes = text.as_bytes();
        let mut starts = vec![0];
        let mut ends = Vec::new();
        let mut i = 0;
        while i < bytes.len() {
            match bytes[i] {
                b'\n' => {
                    ends.push(i);
                    starts.push(i + 1);
                }
                b'\r' => {
                    ends.push(i);
                    if bytes.get(i + 1) == Some(&b'\n') {
                        i += 1;
                    }
                    starts.push(i + 1);
                }
                _ => {}
            }
            i += 1;
        }
        ends.push(bytes.len());
        LineIndex { starts, ends }
    }

    /// How many lines the text has (an empty text, or one ending in a
    /// line break, has an empty last line).
    pub fn lines(&self) -> usize {
        self.starts.len()
    }

    /// The position of byte `offset` of `text` (the text this index was
    /// made from); an offset past the end is the end, one inside a
    /// character is that character's start.
    pub fn position(&self, text: &str, offset: usize) -> Position {
        let mut offset = offset.min(text.len());
        while !text.is_char_boundary(offset) {
            offset -= 1;
        }
        // the last line starting at or before the offset
        let line = self.starts.partition_point(|&s| s <= offset) - 1;
        // an offset inside a line break counts as the end of its line
        let offset = offset.min(self.ends[line]);
        let character: usize = text[self.starts[line]..offset]
            .chars()
            .map(char::len_utf16)
            .sum();
        Position {
            line: u32::try_from(line).unwrap_or(u32::MAX),
            character: u32::try_from(character).unwrap_or(u32::MAX),
        }
    }

    /// The byte offset of `pos` in `text`. A column past the end of its
    /// line is the line's end (as the protocol says); a line past the last
    /// line, or a column between the two halves of a surrogate pair, is an
    /// error.
    pub fn offset(&self, text: &str, pos: Position) -> Result<usize, PositionError> {
        let line = pos.line as usize;
        if line >= self.starts.len() {
            return Err(PositionError::LineOutOfRange {
                line: pos.line,
                lines: self.starts.len(),
            });
        }
        let (start, end) = (self.starts[line], self.ends[line]);
        let want = pos.character as usize;
        let mut units = 0;
        for (i, c) in text[start..end].char_indices() {
            if units == want {
                return Ok(start + i);
            }
            units += c.len_utf16();
            if units > want {
                return Err(PositionError::InsideCharacter {
                    line: pos.line,
                    character: pos.character,
                });
            }
        }
        Ok(end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pos(line: u32, character: u32) -> Position {
        Position { line, character }
    }

    #[test]
    fn every_offset_round_trips_through_its_position() {
        let text = "ab\r\nçd\rx𝄞y\n\n€";
        let idx = LineIndex::new(text);
        assert_eq!(idx.lines(), 5);
        for (o, _) in text.char_indices() {
            let p = idx.position(text, o);
            let back = idx.offset(text, p).expect("a valid position");
            // the LF of a CRLF belongs to the break that starts at its CR
            let want = if text[o..].starts_with('\n') && text[..o].ends_with('\r') {
                o - 1
            } else {
                o
            };
            assert_eq!(back, want, "offset {o} at {p:?}");
        }
        assert_eq!(idx.position(text, text.len()), pos(4, 1));
    }

    #[test]
    fn columns_count_utf16_units() {
        let text = "x𝄞y\n";
        let idx = LineIndex::new(text);
        // 𝄞 is 4 bytes and 2 UTF-16 units
        assert_eq!(idx.position(text, 5), pos(0, 3));
        assert_eq!(idx.offset(text, pos(0, 3)), Ok(5));
        assert_eq!(
            idx.offset(text, pos(0, 2)),
            Err(PositionError::InsideCharacter {
                line: 0,
                character: 2
            })
        );
        // an offset inside a character is its start
        assert_eq!(idx.position(text, 2), pos(0, 1));
    }

    #[test]
    fn positions_past_a_line_clamp_and_past_the_text_fail() {
        let text = "ab\ncd";
        let idx = LineIndex::new(text);
        assert_eq!(idx.offset(text, pos(0, 99)), Ok(2));
        assert_eq!(idx.offset(text, pos(1, u32::MAX)), Ok(5));
        assert_eq!(
            idx.offset(text, pos(2, 0)),
            Err(PositionError::LineOutOfRange { line: 2, lines: 2 })
        );
        assert_eq!(idx.position(text, 999), pos(1, 2));
        let empty = LineIndex::new("");
        assert_eq!(empty.offset("", pos(0, 0)), Ok(0));
        // CR, CRLF and LF each end one line
        assert_eq!(LineIndex::new("a\rb\r\nc\nd").lines(), 4);
    }
}
