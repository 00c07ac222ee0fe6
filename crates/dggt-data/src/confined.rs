//! Paths that untrusted files name (a dataset table's file name, a line of a scene list) must lead to a file
//! inside the folder they are relative to, so that a crafted dataset cannot make a command read a file elsewhere
//! on the machine, or copy one into its output. An absolute path, or one with a `..` component, is refused as
//! written; a path whose existing part leads out of the folder through a symbolic link is refused once resolved:
//! the canonical form of its longest existing ancestor, then the rest, against the folder's canonical form.
//!
//! [`resolved`] and [`is_within`] are the same resolution for paths a user names (an extra output of a command
//! that must not lie in its output folder).

use std::io;
use std::path::{Component, Path, PathBuf};

/// Why a path named by a file does not stay inside its folder.
#[derive(Debug, thiserror::Error)]
pub enum Escape {
    #[error("an empty path, expected a file under {}", root.display())]
    Empty { root: PathBuf },
    #[error("`{}` is absolute, expected a path relative to {}", path.display(), root.display())]
    Absolute { path: PathBuf, root: PathBuf },
    #[error("`{}` has a `..` component, expected a path inside {}", path.display(), root.display())]
    ParentComponent { path: PathBuf, root: PathBuf },
    #[error("`{}` leads outside {} (through a symbolic link, to {})", path.display(), root.display(), resolved.display())]
    Outside { path: PathBuf, root: PathBuf, resolved: PathBuf },
    #[error("`{}` under {} cannot be resolved: {source}", path.display(), root.display())]
    Unresolvable { path: PathBuf, root: PathBuf, source: io::Error },
}

/// `root` joined with `relative`, a path named by an untrusted file, when it stays inside `root`: not empty,
/// not absolute, no `..` component, and not leading out through a symbolic link. A path that does not exist
/// (yet) is checked as far as it exists; reading it then fails naming it.
pub fn confined_path(root: &Path, relative: &Path) -> Result<PathBuf, Escape> {
    let (path, root_buf) = (relative.to_path_buf(), root.to_path_buf());
    if relative.as_os_str().is_empty() {
        return Err(Escape::Empty { root: root_buf });
    }
    for component in relative.components() {
        match component {
            Component::Prefix(_) | Component::RootDir => return Err(Escape::Absolute { path, root: root_buf }),
            Component::ParentDir => return Err(Escape::ParentComponent { path, root: root_buf }),
            Component::CurDir | Component::Normal(_) => {}
        }
    }
    let joined = root.join(relative);
    let unresolvable = |source| Escape::Unresolvable { path: relative.to_path_buf(), root: root.to_path_buf(), source };
    let (resolved_root, resolved_path) =
        (resolved(root).map_err(unresolvable)?, resolved(&joined).map_err(unresolvable)?);
    if !resolved_path.starts_with(&resolved_root) {
        return Err(Escape::Outside { path, root: root_buf, resolved: resolved_path });
    }
    Ok(joined)
}

/// `path` made absolute with its symbolic links followed: the canonical form of its longest existing ancestor,
/// then the remaining components (a `..` among them taking off the component before it).
pub fn resolved(path: &Path) -> io::Result<PathBuf> {
    let absolute = if path.is_absolute() { path.to_path_buf() } else { std::env::current_dir()?.join(path) };
    let components: Vec<Component> = absolute.components().collect();
    let mut failure = None;
    for existing in (1..=components.len()).rev() {
        match components[..existing].iter().collect::<PathBuf>().canonicalize() {
            Ok(mut resolved) => {
                for component in &components[existing..] {
                    match component {
                        Component::ParentDir => {
                            resolved.pop();
                        }
                        Component::Normal(name) => resolved.push(name),
                        Component::Prefix(_) | Component::RootDir | Component::CurDir => {}
                    }
                }
                return Ok(resolved);
            }
            Err(error) => failure = Some(error),
        }
    }
    Err(failure.unwrap_or_else(|| io::Error::new(io::ErrorKind::NotFound, "an empty path")))
}

/// Whether `path` is `folder` or lies inside it, both [`resolved`].
pub fn is_within(path: &Path, folder: &Path) -> io::Result<bool> {
    Ok(resolved(path)?.starts_with(resolved(folder)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_relative_path_inside_the_root_is_joined() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("samples/CAM_FRONT")).unwrap();
        std::fs::write(dir.path().join("samples/CAM_FRONT/a.jpg"), b"x").unwrap();
        for relative in ["samples/CAM_FRONT/a.jpg", "./samples/CAM_FRONT/a.jpg", "samples/CAM_FRONT/missing.jpg"] {
            let path = confined_path(dir.path(), Path::new(relative)).unwrap();
            assert_eq!(path, dir.path().join(relative));
        }
    }

    #[test]
    fn absolute_paths_parent_components_and_empty_paths_are_refused_naming_the_path_and_the_root() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        let cases = [
            ("../../../../etc/passwd", "`..` component"),
            ("samples/../../secret", "`..` component"),
            ("/etc/passwd", "is absolute"),
            ("", "an empty path"),
        ];
        for (relative, why) in cases {
            let error = confined_path(root, Path::new(relative)).unwrap_err().to_string();
            assert!(error.contains(why) && error.contains(&root.display().to_string()), "{relative}: {error}");
            assert!(error.contains(relative), "{relative}: {error}");
        }
    }

    #[cfg(unix)]
    #[test]
    fn a_symbolic_link_leading_out_of_the_root_is_refused_and_one_staying_inside_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let (root, outside) = (dir.path().join("root"), dir.path().join("outside"));
        std::fs::create_dir_all(root.join("samples")).unwrap();
        std::fs::create_dir_all(&outside).unwrap();
        std::fs::write(outside.join("secret"), b"x").unwrap();
        std::fs::write(root.join("samples/inside.bin"), b"x").unwrap();
        std::os::unix::fs::symlink(outside.join("secret"), root.join("samples/file.bin")).unwrap();
        std::os::unix::fs::symlink(&outside, root.join("linked")).unwrap();
        std::os::unix::fs::symlink(root.join("samples/inside.bin"), root.join("alias.bin")).unwrap();
        for relative in ["samples/file.bin", "linked/secret", "linked/not-yet-there"] {
            let error = confined_path(&root, Path::new(relative)).unwrap_err();
            assert!(matches!(error, Escape::Outside { .. }), "{relative}: {error:?}");
            assert!(error.to_string().contains("leads outside"), "{error}");
        }
        assert_eq!(confined_path(&root, Path::new("alias.bin")).unwrap(), root.join("alias.bin"));
        // The root itself may be reached through a link.
        std::os::unix::fs::symlink(&root, dir.path().join("root-link")).unwrap();
        confined_path(&dir.path().join("root-link"), Path::new("samples/inside.bin")).unwrap();
    }

    #[test]
    fn within_compares_resolved_paths_of_files_that_may_not_exist_yet() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir_all(&out).unwrap();
        assert!(is_within(&out, &out).unwrap(), "a folder is within itself");
        assert!(is_within(&out.join("summary.json"), &out).unwrap());
        assert!(is_within(&out.join("new/../recording.rrd"), &out).unwrap());
        assert!(is_within(&dir.path().join("./out/./x.rrd"), &out).unwrap());
        assert!(!is_within(&out.join("../recording.rrd"), &out).unwrap());
        assert!(!is_within(&dir.path().join("out-2/x.rrd"), &out).unwrap(), "a sibling sharing its name's start");
        assert!(is_within(&dir.path().join("later/x.rrd"), &dir.path().join("later")).unwrap(), "neither exists");
    }
}
