//! Text labels drawn into display images, such as the time after the switch in the frames
//! of a Fig. 12 sequence ([`crate::sequence::Sequence::frame_label`]).
//!
//! Not part of the model: a presentation aid. The text is drawn in white on an opaque
//! black box in the top-left corner of the image, with a 5 × 7 pixel bitmap font of our own
//! (digits, lower-case letters and the signs a luminance or a time needs), scaled by a
//! whole number of pixels so that it stays legible on large images. Only the pixels of the
//! box change ([`draw`] returns it).

use crate::{DisplayImage, Error, Result};

/// Width of a glyph cell, font pixels.
pub const GLYPH_WIDTH: usize = 5;
/// Height of a glyph cell, font pixels.
pub const GLYPH_HEIGHT: usize = 7;
/// Space between glyphs and around the text inside the box, font pixels.
const GAP: usize = 1;
/// Padding between the text and the edge of the box, font pixels.
const PADDING: usize = 2;
/// A font pixel is this many image pixels for each such many rows of the image (at least
/// one): the text is about 1/40 of the image's height, legible without hiding the scene.
const ROWS_PER_SCALE: usize = 300;

/// The rectangle of an image a label covers, pixels (top-left corner and size).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LabelBox {
    /// Left column.
    pub x: usize,
    /// Top row.
    pub y: usize,
    /// Width, pixels (clipped to the image).
    pub width: usize,
    /// Height, pixels (clipped to the image).
    pub height: usize,
}

impl LabelBox {
    /// Whether pixel `(x, y)` lies in the box.
    pub fn contains(&self, x: usize, y: usize) -> bool {
        (self.x..self.x + self.width).contains(&x) && (self.y..self.y + self.height).contains(&y)
    }
}

/// The image pixels per font pixel for an image `height` rows tall.
pub fn scale_for(height: usize) -> usize {
    (height / ROWS_PER_SCALE).max(1)
}

/// Draw `text` (one line, of the characters [`glyph`] knows) into the top-left corner of
/// `image`: white (1.0, the display maximum) on black, clipped to the image. Returns the
/// box it covers; every pixel outside it is left as it was.
///
/// ```
/// use visadapt::{DisplayImage, label};
/// let mut image = DisplayImage::default();
/// (image.width, image.height) = (100, 20);
/// for p in [&mut image.r, &mut image.g, &mut image.b] {
///     *p = vec![0.5; 2000];
/// }
/// let b = label::draw(&mut image, "t = 75 s")?;
/// assert_eq!((b.x, b.y, b.width, b.height), (0, 0, 51, 11));
/// assert_eq!(image.g[99], 0.5); // outside the box
/// # Ok::<(), visadapt::Error>(())
/// ```
pub fn draw(image: &mut DisplayImage, text: &str) -> Result<LabelBox> {
    let glyphs = text
        .chars()
        .map(|c| {
            glyph(c).ok_or_else(|| {
                Error::invalid(
                    "label",
                    format!("{c:?}"),
                    "is not a character of the label font",
                )
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let (w, h) = (image.width, image.height);
    if [&image.r, &image.g, &image.b]
        .iter()
        .any(|p| p.len() != w * h)
    {
        return Err(Error::invalid(
            "display image",
            format!("{w}x{h}"),
            "has planes of another size",
        ));
    }
    let s = scale_for(h);
    let text_width = glyphs.len() * (GLYPH_WIDTH + GAP) - GAP.min(glyphs.len());
    let full = LabelBox {
        x: 0,
        y: 0,
        width: s * (text_width + 2 * PADDING),
        height: s * (GLYPH_HEIGHT + 2 * PADDING),
    };
    let clipped = LabelBox {
        width: full.width.min(w),
        height: full.height.min(h),
        ..full
    };
    for y in 0..clipped.height {
        for x in 0..clipped.width {
            // The font pixel under image pixel (x, y), if it is ink.
            let (fx, fy) = ((x / s).checked_sub(PADDING), (y / s).checked_sub(PADDING));
            let ink = match (fx, fy) {
                (Some(fx), Some(fy)) if fy < GLYPH_HEIGHT => {
                    let (cell, col) = (fx / (GLYPH_WIDTH + GAP), fx % (GLYPH_WIDTH + GAP));
                    col < GLYPH_WIDTH
                        && glyphs
                            .get(cell)
                            .is_some_and(|g| g[fy] >> (GLYPH_WIDTH - 1 - col) & 1 == 1)
                }
                _ => false,
            };
            let v = if ink { 1.0 } else { 0.0 };
            let i = y * w + x;
            (image.r[i], image.g[i], image.b[i]) = (v, v, v);
        }
    }
    Ok(clipped)
}

/// The 5 × 7 bitmap of a character, one row per entry from the top, bit 4 the leftmost
/// column; `None` for a character the font lacks. It has the digits, the lower-case
/// letters, the space and `. , : / = + - ( ) ² %`.
pub fn glyph(c: char) -> Option<[u8; GLYPH_HEIGHT]> {
    let rows: [u8; GLYPH_HEIGHT] = match c {
        ' ' => [0, 0, 0, 0, 0, 0, 0],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        ',' => [0, 0, 0, 0, 0x0C, 0x04, 0x08],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0],
        '/' => [0, 0x01, 0x02, 0x04, 0x08, 0x10, 0],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0],
        '+' => [0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '²' => [0x0C, 0x12, 0x04, 0x08, 0x1E, 0, 0],
        'a' => [0, 0, 0x0E, 0x01, 0x0F, 0x11, 0x0F],
        'b' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E],
        'c' => [0, 0, 0x0E, 0x10, 0x10, 0x11, 0x0E],
        'd' => [0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F],
        'e' => [0, 0, 0x0E, 0x11, 0x1F, 0x10, 0x0E],
        'f' => [0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08],
        'g' => [0, 0, 0x0F, 0x11, 0x0F, 0x01, 0x0E],
        'h' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11],
        'i' => [0x04, 0, 0x0C, 0x04, 0x04, 0x04, 0x0E],
        'j' => [0x02, 0, 0x06, 0x02, 0x02, 0x12, 0x0C],
        'k' => [0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12],
        'l' => [0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'm' => [0, 0, 0x1A, 0x15, 0x15, 0x11, 0x11],
        'n' => [0, 0, 0x16, 0x19, 0x11, 0x11, 0x11],
        'o' => [0, 0, 0x0E, 0x11, 0x11, 0x11, 0x0E],
        'p' => [0, 0, 0x1E, 0x11, 0x1E, 0x10, 0x10],
        'q' => [0, 0, 0x0D, 0x13, 0x0F, 0x01, 0x01],
        'r' => [0, 0, 0x16, 0x19, 0x10, 0x10, 0x10],
        's' => [0, 0, 0x0E, 0x10, 0x0E, 0x01, 0x1E],
        't' => [0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06],
        'u' => [0, 0, 0x11, 0x11, 0x11, 0x13, 0x0D],
        'v' => [0, 0, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'w' => [0, 0, 0x11, 0x11, 0x15, 0x15, 0x0A],
        'x' => [0, 0, 0x11, 0x0A, 0x04, 0x0A, 0x11],
        'y' => [0, 0, 0x11, 0x11, 0x0F, 0x01, 0x0E],
        'z' => [0, 0, 0x1F, 0x02, 0x04, 0x08, 0x1F],
        _ => return None,
    };
    Some(rows)
}
