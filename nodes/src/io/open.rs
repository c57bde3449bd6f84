//! Opening the files users name, and the files named inside them (a scene's PLY meshes, a
//! tileset's content, a view's images): only regular files, and never blocking on the way. A
//! FIFO opened for reading waits for a writer forever, and a device can stream without end, so
//! the open itself is non-blocking and the file's type is checked on the open handle, before a
//! byte is read.

use std::fs::{File, FileType, OpenOptions};
use std::io::{self, Read};
use std::path::Path;

/// What a file that is neither a regular file nor a folder is, for messages.
pub fn describe_file_type(t: &FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_fifo() {
        "a FIFO (named pipe)"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_symlink() {
        "a symlink"
    } else {
        "a special file"
    }
}

/// `path` opened for reading if it is a regular file (symlinks followed); a folder, FIFO,
/// socket or device is an `InvalidInput` error saying which, and nothing waits on it.
pub fn open_regular(path: impl AsRef<Path>) -> io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    // O_NONBLOCK: opening a FIFO returns at once; on a regular file it changes nothing.
    let f = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path.as_ref())?;
    let t = f.metadata()?.file_type();
    if t.is_file() {
        return Ok(f);
    }
    let found = if t.is_dir() {
        "a folder"
    } else {
        describe_file_type(&t)
    };
    Err(io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("expected a regular file, found {found}"),
    ))
}

/// The whole of regular file `path` ([`open_regular`]).
pub fn read_regular(path: impl AsRef<Path>) -> io::Result<Vec<u8>> {
    let f = open_regular(path)?;
    let len = f.metadata().map_or(0, |m| m.len());
    // A file read whole is one buffer: past the budget (a sparse file of a terabyte) it is an
    // error, and below it an allocation that fails is one too, never an abort.
    let most = crate::params::MAX_BYTES;
    if len > most {
        return Err(io::Error::new(
            io::ErrorKind::OutOfMemory,
            format!("a file of {len} bytes, past the {most} a file read whole may take"),
        ));
    }
    let mut out = Vec::new();
    out.try_reserve_exact(len as usize).map_err(|_| {
        io::Error::new(
            io::ErrorKind::OutOfMemory,
            format!("a file of {len} bytes, more than this machine can hold in memory"),
        )
    })?;
    f.take(most).read_to_end(&mut out)?;
    Ok(out)
}

/// Regular file `path` as UTF-8 text ([`open_regular`]).
pub fn read_regular_to_string(path: impl AsRef<Path>) -> io::Result<String> {
    String::from_utf8(read_regular(path)?).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!(
                "not UTF-8 text (invalid byte at offset {})",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fifos_and_folders_are_refused_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        // Would block forever without O_NONBLOCK: nobody writes to the pipe.
        let e = read_regular(&fifo).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert!(e.to_string().contains("a FIFO"), "{e}");
        let e = read_regular(dir.path()).unwrap_err();
        assert!(e.to_string().contains("a folder"), "{e}");
        let e = read_regular(Path::new("/dev/zero")).unwrap_err();
        assert!(e.to_string().contains("character device"), "{e}");
        let file = dir.path().join("a.txt");
        std::fs::write(&file, "text").unwrap();
        assert_eq!(read_regular_to_string(&file).unwrap(), "text");
        // Sparse: no disk, and past the budget of one buffer; refused before any allocation.
        let huge = dir.path().join("huge");
        std::fs::File::create(&huge)
            .unwrap()
            .set_len(crate::params::MAX_BYTES + 1)
            .unwrap();
        let e = read_regular(&huge).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::OutOfMemory, "{e}");
    }
}
