//! The streaming binary PLY writer.

use crate::{generate_counted, GenError, GenSpec, MeshSink};
use megaray_base::Progress;
use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use tempfile::NamedTempFile;

/// Buffer size of each output stream.
const BUF: usize = 8 << 20;
/// PLY `int` indices: at most this many vertices.
const MAX_VERTS: u64 = 1 << 31;
/// After this many bytes, the sized writer asks the kernel to start writing back (Linux).
const KICK: u64 = 64 << 20;

/// The header, byte for byte the Embree peer's `--dump-ply` header.
fn header(verts: u64, tris: u64) -> String {
    format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {verts}\nproperty float x\nproperty float y\n\
         property float z\nelement face {tris}\nproperty list uchar int vertex_indices\nend_header\n"
    )
}

enum Mode {
    /// Counts unknown: vertices and faces each go to a temporary file; `finish` writes the
    /// output (a third temporary file) from the header and both.
    Unsized { verts: BufWriter<NamedTempFile>, faces: BufWriter<NamedTempFile> },
    /// Counts declared up front: the output's temporary file gets the header and vertices
    /// through one handle and the faces, at their final offset, through another.
    Sized { out: BufWriter<NamedTempFile>, faces: BufWriter<File>, verts: u64, tris: u64, unkicked: u64 },
}

/// Starts the write-back of `file`'s dirty pages without waiting for it, so that the disk
/// works while the model is generated rather than all at once in the final `fsync`.
#[cfg(target_os = "linux")]
fn start_writeback(file: &File) {
    use std::os::unix::io::AsRawFd;
    // SAFETY: a plain syscall on a file descriptor we own; it only schedules I/O, and a
    // failure (it is advisory) is ignored.
    unsafe {
        libc::sync_file_range(file.as_raw_fd(), 0, 0, libc::SYNC_FILE_RANGE_WRITE);
    }
}

#[cfg(not(target_os = "linux"))]
fn start_writeback(_: &File) {}

/// A streaming writer of binary little-endian PLY files, in bounded memory.
///
/// It is a [`MeshSink`]: feed it chunks (their indices global, as `MeshSink` says) and call
/// [`finish`](PlyWriter::finish). The layout is exactly that of the Embree peer harness's
/// `--dump-ply`: `element vertex N` with `float x, y, z`, then `element face M` with
/// `property list uchar int vertex_indices`, every face a triangle.
///
/// Nothing appears at `path` until `finish` succeeds: everything is written to temporary files
/// in the output's directory (so that the final rename is atomic), and dropping the writer
/// without `finish`, or any error, removes them. Errors name the output file, e.g.
/// `out.ply: cannot write: No space left on device (os error 28)`.
///
/// ```
/// use megaray_gen::{MeshSink, PlyWriter};
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("tri.ply");
/// let mut w = PlyWriter::create(&path).unwrap();
/// w.chunk(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[0, 1, 2]]).unwrap();
/// assert_eq!(w.finish().unwrap(), (3, 1));
/// assert!(std::fs::read(&path).unwrap().starts_with(b"ply\nformat binary_little_endian 1.0\n"));
/// ```
pub struct PlyWriter {
    path: PathBuf,
    mode: Mode,
    verts: u64,
    tris: u64,
    scratch: Vec<u8>,
}

/// The directory a temporary file for `path` goes to.
fn dir_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

fn temp_next_to(path: &Path, what: &str) -> Result<NamedTempFile, GenError> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    tempfile::Builder::new()
        .prefix(&format!(".{name}."))
        .suffix(&format!(".{what}.tmp"))
        .tempfile_in(dir_of(path))
        .map_err(|e| GenError::io(path, "cannot create", e))
}

impl PlyWriter {
    /// Starts writing `path` when the counts are not known in advance. Fails at once (naming
    /// `path`) when its directory does not exist or is not writable.
    pub fn create(path: &Path) -> Result<Self, GenError> {
        let verts = BufWriter::with_capacity(BUF, temp_next_to(path, "vertices")?);
        let faces = BufWriter::with_capacity(BUF, temp_next_to(path, "faces")?);
        Ok(PlyWriter {
            path: path.to_path_buf(),
            mode: Mode::Unsized { verts, faces },
            verts: 0,
            tris: 0,
            scratch: Vec::new(),
        })
    }

    /// Starts writing `path` for a mesh of exactly `verts` vertices and `tris` triangles: the
    /// data is written once, in place, which halves the disk traffic of [`create`](Self::create).
    /// `finish` fails if the counts fed differ from the declared ones.
    pub fn with_counts(path: &Path, verts: u64, tris: u64) -> Result<Self, GenError> {
        if verts > MAX_VERTS {
            return Err(GenError::sink(
                path.display().to_string(),
                format!("{verts} vertices: more than PLY int indices can address"),
            ));
        }
        let tmp = temp_next_to(path, "ply")?;
        let wr = |e| GenError::io(path, "cannot write", e);
        let head = header(verts, tris);
        let mut faces = tmp.reopen().map_err(|e| GenError::io(path, "cannot open", e))?;
        faces.seek(SeekFrom::Start(head.len() as u64 + 12 * verts)).map_err(wr)?;
        let mut out = BufWriter::with_capacity(BUF, tmp);
        out.write_all(head.as_bytes()).map_err(wr)?;
        Ok(PlyWriter {
            path: path.to_path_buf(),
            mode: Mode::Sized { out, faces: BufWriter::with_capacity(BUF, faces), verts, tris, unkicked: 0 },
            verts: 0,
            tris: 0,
            scratch: Vec::new(),
        })
    }

    /// Writes the header, joins the parts, and renames the file into place. Returns
    /// `(vertices, triangles)` written.
    pub fn finish(self) -> Result<(u64, u64), GenError> {
        let path = self.path;
        let wr = |e| GenError::io(&path, "cannot write", e);
        let done = match self.mode {
            Mode::Unsized { verts, faces } => {
                let mut verts = verts.into_inner().map_err(|e| wr(e.into_error()))?;
                let mut faces = faces.into_inner().map_err(|e| wr(e.into_error()))?;
                let out = temp_next_to(&path, "ply")?;
                let mut w = BufWriter::with_capacity(BUF, out);
                w.write_all(header(self.verts, self.tris).as_bytes()).map_err(wr)?;
                w.flush().map_err(wr)?;
                let mut out = w.into_inner().map_err(|e| wr(e.into_error()))?;
                for part in [&mut verts, &mut faces] {
                    part.as_file_mut().seek(SeekFrom::Start(0)).map_err(wr)?;
                    io::copy(part.as_file_mut(), out.as_file_mut()).map_err(wr)?;
                }
                out
            }
            Mode::Sized { out, faces, verts, tris, .. } => {
                if (self.verts, self.tris) != (verts, tris) {
                    return Err(GenError::sink(
                        path.display().to_string(),
                        format!(
                            "got {} vertices and {} triangles, but {verts} and {tris} were declared",
                            self.verts, self.tris
                        ),
                    ));
                }
                let faces = faces.into_inner().map_err(|e| wr(e.into_error()))?;
                faces.sync_all().map_err(wr)?;
                out.into_inner().map_err(|e| wr(e.into_error()))?
            }
        };
        done.as_file().sync_all().map_err(wr)?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            done.as_file()
                .set_permissions(std::fs::Permissions::from_mode(0o644))
                .map_err(|e| GenError::io(&path, "cannot set permissions of", e))?;
        }
        done.persist(&path).map_err(|e| GenError::io(&path, "cannot rename into place", e.error))?;
        Ok((self.verts, self.tris))
    }
}

impl MeshSink for PlyWriter {
    fn chunk(&mut self, verts: &[[f32; 3]], tris: &[[u32; 3]]) -> Result<(), GenError> {
        let nv = self.verts + verts.len() as u64;
        if nv > MAX_VERTS {
            return Err(GenError::sink(
                self.path.display().to_string(),
                "more than 2^31 vertices: PLY int indices cannot address them",
            ));
        }
        let max = tris.iter().flatten().copied().max().unwrap_or(0) as u64;
        if !tris.is_empty() && max >= nv {
            return Err(GenError::sink(
                self.path.display().to_string(),
                format!("vertex index {max} out of range: only {nv} vertices so far"),
            ));
        }
        self.scratch.clear();
        self.scratch.reserve(13 * tris.len());
        for t in tris {
            self.scratch.push(3);
            for &i in t {
                self.scratch.extend_from_slice(&(i as i32).to_le_bytes());
            }
        }
        let vbytes: &[u8] = if cfg!(target_endian = "little") { bytemuck::cast_slice(verts) } else { &[] };
        let path = &self.path;
        let wr = |e| GenError::io(path, "cannot write", e);
        let (vw, fw): (&mut dyn Write, &mut dyn Write) = match &mut self.mode {
            Mode::Unsized { verts, faces } => (verts, faces),
            Mode::Sized { out, faces, verts: dv, tris: dt, unkicked } => {
                if nv > *dv || self.tris + tris.len() as u64 > *dt {
                    return Err(GenError::sink(
                        path.display().to_string(),
                        format!("more than the declared {dv} vertices and {dt} triangles"),
                    ));
                }
                *unkicked += vbytes.len() as u64 + self.scratch.len() as u64;
                if *unkicked >= KICK {
                    *unkicked = 0;
                    start_writeback(faces.get_ref());
                }
                (out, faces)
            }
        };
        if cfg!(target_endian = "little") {
            vw.write_all(vbytes).map_err(wr)?;
        } else {
            for v in verts.iter().flatten() {
                vw.write_all(&v.to_le_bytes()).map_err(wr)?;
            }
        }
        fw.write_all(&self.scratch).map_err(wr)?;
        self.verts = nv;
        self.tris += tris.len() as u64;
        Ok(())
    }
}

/// Generates `spec` into the binary PLY file `out` (see [`PlyWriter`]) and returns
/// `(vertices, triangles)`. The counts are known in advance ([`GenSpec::counts`]), so the data
/// is written once, in place; `out` appears only when complete.
pub fn write_ply(spec: &GenSpec, out: &Path, progress: &dyn Progress) -> Result<(u64, u64), GenError> {
    let (v, t) = spec.counts();
    let mut w = PlyWriter::with_counts(out, v, t)?;
    generate_counted(spec, (v, t), &mut w, progress)?;
    w.finish()
}
