//! Reading the files riprs writes and reads back (an experiment file, the identification
//! and tuning records beside a rig file): one reader, [`read_regular`], for the experiment's
//! reader ([`crate::spec::read_text`]), the pre-flight and the stored swing-up verdict. It
//! imports nothing of the crate, so that every module may use it.

use std::path::Path;

/// Largest file [`read_regular`] reads (bytes): what riprs writes (an experiment, an
/// identification, a tuning record) is a few kilobytes; the bound keeps a path that names a
/// log or an image from filling memory.
pub const MAX_FILE_BYTES: u64 = 4 << 20;

/// The bytes of the file at `path`: only a regular file (symbolic links followed), at most
/// [`MAX_FILE_BYTES`]. Anything else is refused before it is opened, so that a FIFO (whose
/// opening blocks until a writer comes) or a device such as `/dev/zero` (which never ends)
/// named like an experiment file or a record beside one can neither hang the reader nor
/// fill its memory. The error says what is wrong (not the path); [`std::io::ErrorKind::NotFound`]
/// when nothing is there.
pub fn read_regular(path: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let not_regular = |meta: &std::fs::Metadata| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("not a regular file ({})", file_kind(meta)),
        )
    };
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    let file = std::fs::File::open(path)?;
    // What was opened may not be what was looked at, if the path changed in between.
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    let mut bytes = Vec::new();
    file.take(MAX_FILE_BYTES + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {MAX_FILE_BYTES} bytes, not a file riprs wrote"),
        ));
    }
    Ok(bytes)
}

/// What a file that is not a regular one is, for an error.
fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    "another kind of file"
}
