//! The one reader of the experiment file and the records beside it (`spec::read_regular`,
//! under `spec::read_text`): regular files only, refused before opening otherwise, and bounded.

use std::path::PathBuf;

use rip_core::spec::{read_regular, read_text, MAX_FILE_BYTES};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rip-core-read-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn a_fifo_a_device_and_a_directory_are_refused_without_blocking() {
    let d = dir("kinds");
    let fifo = d.join("x.tune.toml");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a NUL-terminated path; mkfifo touches nothing else.
    assert_eq!(unsafe { libc_mkfifo(c.as_ptr(), 0o644) }, 0);
    let zero = d.join("y.identification.toml");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    for (path, kind) in [
        (&fifo, "a FIFO"),
        (&zero, "a character device"),
        (&d, "a directory"),
    ] {
        let e = read_regular(path).unwrap_err();
        assert!(
            e.to_string()
                .contains(&format!("not a regular file ({kind})")),
            "{e}"
        );
        let e = read_text(path).unwrap_err();
        assert_eq!(e.file.as_deref(), Some(path.to_str().unwrap()), "{e}");
        assert!(
            e.reason.starts_with("cannot read: not a regular file"),
            "{e}"
        );
    }
    let e = read_regular(&d.join("absent.toml")).unwrap_err();
    assert_eq!(e.kind(), std::io::ErrorKind::NotFound);
}

#[test]
fn a_file_past_the_bound_is_refused_and_one_at_it_is_read() {
    let d = dir("size");
    let at = d.join("at.toml");
    std::fs::write(&at, vec![b'#'; MAX_FILE_BYTES as usize]).unwrap();
    assert_eq!(read_regular(&at).unwrap().len() as u64, MAX_FILE_BYTES);
    let past = d.join("past.toml");
    std::fs::write(&past, vec![b'#'; MAX_FILE_BYTES as usize + 1]).unwrap();
    let e = read_text(&past).unwrap_err();
    assert!(e.reason.contains("larger than"), "{e}");
}

extern "C" {
    #[link_name = "mkfifo"]
    fn libc_mkfifo(path: *const std::ffi::c_char, mode: u32) -> i32;
}
