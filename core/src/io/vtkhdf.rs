//! VTKHDF output: one HDF5 file holding every frame of a run, read natively by ParaView (5.13 and
//! later) and by VTK's `vtkHDFReader`.
//!
//! The file is a temporal `PartitionedDataSetCollection` (VTKHDF 2.1): each picture of a frame
//! (the material points or spheres, the contact network, the walls...) is an `UnstructuredGrid`
//! block of its own under `/VTKHDF/<name>`, listed in `/VTKHDF/Assembly` by a soft link: points as
//! vertex cells, contacts as lines, walls as polygons. A frame appends to every block: its points
//! and cells at the end of the block's arrays, and one row of read offsets in the block's `Steps`
//! group, all blocks sharing the same time values. (Unstructured grids rather than poly data:
//! VTK's reader finds the cells of a poly-data frame that follows a frame without cells of that
//! kind at the wrong offset, as with the contact network before the first contact.)
//!
//! Every point array has as many rows as the block has points in that frame, and every cell array
//! as many as it has cells (a field missing from a frame is written as zeros): the reader then
//! slices the arrays by the geometry's offsets, and no per-array offsets are written.
//!
//! A frame at a time not after the last one's (a run resumed from a checkpoint, the last good
//! state written again after a failed step) first drops the frames from that time on, as the
//! `.pvd` series do. The file is flushed after each frame.

use super::vtk::{Field, PolyData};
use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use hdf5::types::FixedAscii;
use hdf5::{Dataset, File, Group, H5Type};
use ndarray::{ArrayView1, ArrayView2};
use std::path::{Path, PathBuf};

/// The VTKHDF version written: 2.1 is the first with `PartitionedDataSetCollection`.
const VERSION: [i64; 2] = [2, 1];
/// VTK's cell types.
const VTK_VERTEX: u8 = 1;
const VTK_LINE: u8 = 3;
const VTK_POLYGON: u8 = 7;
/// Rows per chunk of the appended arrays: few writes a frame, and a frame of a few points does
/// not grow the file by much.
const CHUNK_ROWS: usize = 4096;
/// Rows per chunk of the per-frame counts and offsets.
const STEP_CHUNK_ROWS: usize = 64;

/// One block of one frame: points, the cells over them, and data per point and per cell.
pub struct BlockFrame<'a> {
    pub points: &'a [Vec3],
    /// One vertex cell per point (material points and spheres), so that ParaView draws them.
    pub vertices: bool,
    pub lines: &'a [[u32; 2]],
    pub polygons: &'a [Vec<u32>],
    pub point_fields: &'a [Field],
    /// One value per cell: vertices, then lines, then polygons.
    pub cell_fields: &'a [Field],
}

impl<'a> BlockFrame<'a> {
    /// Points drawn as vertices, with their fields.
    pub fn points(points: &'a [Vec3], fields: &'a [Field]) -> BlockFrame<'a> {
        BlockFrame { points, vertices: true, lines: &[], polygons: &[], point_fields: fields, cell_fields: &[] }
    }

    /// Lines and polygons (contacts, walls).
    pub fn poly(data: &'a PolyData) -> BlockFrame<'a> {
        BlockFrame {
            points: &data.points,
            vertices: false,
            lines: &data.lines,
            polygons: &data.polygons,
            point_fields: &data.point_fields,
            cell_fields: &data.cell_fields,
        }
    }

    fn cell_count(&self) -> usize {
        let vertices = if self.vertices { self.points.len() } else { 0 };
        vertices + self.lines.len() + self.polygons.len()
    }

    /// The cells in VTK's order (vertices, lines, polygons): their types, offsets (from 0, one
    /// more than the cells) and connectivity.
    fn cells(&self) -> (Vec<u8>, Vec<i64>, Vec<i64>) {
        let mut types = Vec::with_capacity(self.cell_count());
        let mut offsets = Vec::with_capacity(self.cell_count() + 1);
        let mut ids = Vec::new();
        offsets.push(0i64);
        if self.vertices {
            for k in 0..self.points.len() {
                types.push(VTK_VERTEX);
                ids.push(k as i64);
                offsets.push(ids.len() as i64);
            }
        }
        for line in self.lines {
            types.push(VTK_LINE);
            ids.extend(line.iter().map(|&i| i as i64));
            offsets.push(ids.len() as i64);
        }
        for polygon in self.polygons {
            types.push(VTK_POLYGON);
            ids.extend(polygon.iter().map(|&i| i as i64));
            offsets.push(ids.len() as i64);
        }
        (types, offsets, ids)
    }
}

/// A run's frames in one `.vtkhdf` file.
pub struct VtkHdfWriter {
    file: File,
    path: PathBuf,
    times: Vec<f64>,
    /// Block names in the order they were made (their `Index`).
    blocks: Vec<String>,
    /// Said once to the user: why an earlier file was set aside.
    note: Option<String>,
}

fn h5(path: &Path) -> impl Fn(hdf5::Error) -> GraniteError + '_ {
    move |e| GraniteError::Other(format!("{}: {e}", path.display()))
}

/// A name HDF5 and the VTKHDF reader accept as an array name (no `/` or `.`).
fn array_name(name: &str) -> String {
    name.replace(['/', '.'], "_")
}

impl VtkHdfWriter {
    /// A new file at `path`, replacing any file there.
    pub fn create(path: &Path) -> Result<VtkHdfWriter> {
        if let Some(dir) = path.parent() {
            super::output_folder(dir.parent().unwrap_or(dir), dir)?;
        }
        // HDF5 opens what a name points to: a link left there goes first.
        if std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink()) {
            std::fs::remove_file(path).map_err(|e| GraniteError::io(path, e))?;
        }
        let err = h5(path);
        let file = File::create(path).map_err(&err)?;
        close_on_exec(&file);
        let root = ordered_group(&file, "VTKHDF").map_err(&err)?;
        write_version_and_type(&root, "PartitionedDataSetCollection").map_err(&err)?;
        ordered_group(&root, "Assembly").map_err(&err)?;
        file.flush().map_err(&err)?;
        Ok(VtkHdfWriter { file, path: path.to_path_buf(), times: Vec::new(), blocks: Vec::new(), note: None })
    }

    /// The file at `path` continued by a run resumed at `time`: its frames before that time are
    /// kept, the later ones dropped (the resumed run writes them again). They are copied into a
    /// new file that replaces the old one: a run killed while it wrote a frame can leave HDF5's
    /// indexes in the old file in a state that misplaces later writes (measured: a resumed run
    /// appending in place wrote its first frame wrong after about one kill in a hundred), while
    /// what it had written whole reads back. A missing file starts a new one; one that cannot be
    /// read as a series of this writer is moved aside to `<path>.damaged` and a new one started.
    pub fn resume(path: &Path, time: f64) -> Result<VtkHdfWriter> {
        if !path.exists() {
            return Self::create(path);
        }
        // Open in another program (HDF5 locks what it opens): the file may be whole, and must not
        // be set aside. Asked of the lock itself: HDF5's messages about a damaged file can hold
        // the word too (`sblock->base_addr`).
        if locked_elsewhere(path) {
            return Err(GraniteError::Other(format!(
                "{}: the file is open in another program (ParaView?), which holds a lock on it; close it there \
                 and resume again",
                path.display()
            )));
        }
        let read = File::open(path).and_then(|old| whole_series(&old).map(|(blocks, times)| (old, blocks, times)));
        let (old, blocks, times) = match read {
            Ok(found) => found,
            Err(e) => return Self::set_aside(path, &e.to_string()),
        };
        let keep = times.iter().take_while(|&&t| t < time).count();
        let fresh = path.with_extension("vtkhdf.partial");
        let mut writer = Self::create(&fresh)?;
        let copy = |writer: &VtkHdfWriter| -> hdf5::Result<()> {
            let root = writer.file.group("VTKHDF")?;
            let old_root = old.group("VTKHDF")?;
            for (index, name) in blocks.iter().enumerate() {
                copy_block(&old_root.group(name)?, &root, name, index as i64, keep)?;
            }
            writer.file.flush()
        };
        if let Err(e) = copy(&writer) {
            // Frames listed whole whose rows cannot be read: the old file is damaged after all.
            drop(writer);
            let _ = std::fs::remove_file(&fresh);
            return Self::set_aside(path, &e.to_string());
        }
        drop(old);
        std::fs::rename(&fresh, path).map_err(|e| GraniteError::io(path, e))?;
        writer.path = path.to_path_buf();
        writer.blocks = blocks;
        writer.times = times[..keep].to_vec();
        Ok(writer)
    }

    /// Moves a file that cannot be continued (`why`: HDF5's reason) to `<path>.damaged` (what it
    /// holds may still be read there) and starts a new one, which says so in
    /// [`VtkHdfWriter::take_note`].
    fn set_aside(path: &Path, why: &str) -> Result<VtkHdfWriter> {
        let aside = path.with_extension("vtkhdf.damaged");
        std::fs::rename(path, &aside).map_err(|e| GraniteError::io(path, e))?;
        let mut writer = Self::create(path)?;
        let why = why.lines().next().unwrap_or(why);
        writer.note = Some(format!(
            "{} could not be continued ({why}): it was moved to {} and a new file started",
            path.display(),
            aside.display()
        ));
        Ok(writer)
    }

    /// What the user should hear of how the file was opened (set aside on resume), once.
    pub fn take_note(&mut self) -> Option<String> {
        self.note.take()
    }

    pub fn frames(&self) -> usize {
        self.times.len()
    }

    /// Appends one frame of `blocks` (by name) at `time`. A block seen for the first time gets
    /// empty frames before this one; a block missing from this frame gets an empty one.
    pub fn write_frame(&mut self, time: f64, blocks: &[(&str, BlockFrame)]) -> Result<()> {
        self.drop_frames_from(time)?;
        let err = h5(&self.path);
        let root = self.file.group("VTKHDF").map_err(&err)?;
        for (name, _) in blocks {
            if !self.blocks.iter().any(|b| b == name) {
                let block = create_block(&root, name, self.blocks.len() as i64).map_err(&err)?;
                for &t in &self.times {
                    append_frame(&block, t, None).map_err(&err)?;
                }
                self.blocks.push(name.to_string());
            }
        }
        // Every block's data first, then every block's listing: a write that fails (a full disk)
        // leaves no block listing a frame whose data is not in the file.
        let mut ends = Vec::with_capacity(self.blocks.len());
        for name in &self.blocks {
            let block = root.group(name).map_err(&err)?;
            let frame = blocks.iter().find(|(n, _)| n == name).map(|(_, f)| f);
            ends.push(append_frame_data(&block, frame).map_err(&err)?);
        }
        self.file.flush().map_err(&err)?;
        for (name, end) in self.blocks.iter().zip(&ends) {
            list_frame(&root.group(name).map_err(&err)?, time, end).map_err(&err)?;
        }
        self.times.push(time);
        self.file.flush().map_err(&err)
    }

    /// Drops the frames at `time` and later.
    fn drop_frames_from(&mut self, time: f64) -> Result<()> {
        let keep = self.times.iter().take_while(|&&t| t < time).count();
        if keep == self.times.len() {
            return Ok(());
        }
        let err = h5(&self.path);
        let root = self.file.group("VTKHDF").map_err(&err)?;
        for name in &self.blocks {
            truncate_block(&root.group(name).map_err(&err)?, keep).map_err(&err)?;
        }
        self.times.truncate(keep);
        self.file.flush().map_err(&err)
    }
}

/// The blocks of a file (in their `Index` order) and the times of the frames that every block
/// holds whole: a run stopped while it wrote a frame may have left part of it.
fn whole_series(file: &File) -> hdf5::Result<(Vec<String>, Vec<f64>)> {
    let root = file.group("VTKHDF")?;
    let mut indexed = Vec::new();
    for name in root.member_names()? {
        if name != "Assembly" {
            let index: i64 = root.group(&name)?.attr("Index")?.read_scalar()?;
            indexed.push((index, name));
        }
    }
    indexed.sort();
    let blocks: Vec<String> = indexed.into_iter().map(|(_, name)| name).collect();
    let mut times: Option<Vec<f64>> = None;
    for name in &blocks {
        let block = root.group(name)?;
        let whole = whole_frames(&block)?;
        let values: Vec<f64> = block.dataset("Steps/Values")?.read_raw()?;
        let values = &values[..whole];
        times = Some(match times {
            None => values.to_vec(),
            Some(t) => {
                let n = t.len().min(values.len());
                if t[..n] != values[..n] {
                    return Err(hdf5::Error::from(format!(
                        "block `{name}` has other frame times than the first block"
                    )));
                }
                t[..n].to_vec()
            }
        });
    }
    Ok((blocks, times.unwrap_or_default()))
}

/// The rows a block's first `keep` frames take in each of its arrays, by the array's path.
fn kept_rows(block: &Group, keep: usize) -> hdf5::Result<Vec<(String, usize)>> {
    let kept = |count: &str| -> hdf5::Result<usize> {
        Ok(block.dataset(count)?.read_raw::<i64>()?.iter().take(keep).sum::<i64>() as usize)
    };
    let [point_rows, cell_rows, id_rows] = [kept(COUNTS[0])?, kept(COUNTS[1])?, kept(COUNTS[2])?];
    let mut rows: Vec<(String, usize)> = vec![
        ("Points".into(), point_rows),
        ("Types".into(), cell_rows),
        ("Offsets".into(), cell_rows + keep),
        ("Connectivity".into(), id_rows),
    ];
    rows.extend(COUNTS.iter().map(|c| (c.to_string(), keep)));
    rows.extend(STEP_LISTS.iter().map(|l| (format!("Steps/{l}"), keep)));
    for (group, n) in [("PointData", point_rows), ("CellData", cell_rows)] {
        for name in block.group(group)?.member_names()? {
            rows.push((format!("{group}/{name}"), n));
        }
    }
    Ok(rows)
}

/// A new block `name` under `root` holding the first `keep` frames of block `from`.
fn copy_block(from: &Group, root: &Group, name: &str, index: i64, keep: usize) -> hdf5::Result<()> {
    let block = create_block(root, name, index)?;
    for (path, rows) in kept_rows(from, keep)? {
        let source = from.dataset(&path)?;
        let columns = source.shape().get(1).copied().unwrap_or(1);
        let target = match block.dataset(&path) {
            Ok(d) => d,
            Err(_) => {
                let (group, array) = path.split_once('/').unwrap_or(("", path.as_str()));
                let group = block.group(group)?;
                if source.dtype()?.is::<i64>() {
                    growable::<i64>(&group, array, columns, CHUNK_ROWS)?
                } else {
                    growable::<f64>(&group, array, columns, CHUNK_ROWS)?
                }
            }
        };
        if rows == 0 {
            continue;
        }
        if source.dtype()?.is::<f64>() {
            copy_rows::<f64>(&source, &target, rows, columns)?;
        } else if source.dtype()?.is::<u8>() {
            copy_rows::<u8>(&source, &target, rows, columns)?;
        } else {
            copy_rows::<i64>(&source, &target, rows, columns)?;
        }
    }
    block.group("Steps")?.attr("NSteps")?.write_scalar(&(keep as i64))
}

/// Appends the first `rows` rows of `source` to `target`.
fn copy_rows<T: H5Type + Clone>(source: &Dataset, target: &Dataset, rows: usize, columns: usize) -> hdf5::Result<()> {
    let values: Vec<T> = if source.ndim() == 1 {
        source.read_slice_1d::<T, _>(0..rows)?.to_vec()
    } else {
        source.read_slice_2d::<T, _>((0..rows, 0..columns))?.iter().cloned().collect()
    };
    append(target, &values, columns)
}

/// Whether another program holds HDF5's lock on the file (an exclusive `flock` cannot be taken
/// now). HDF5 takes that lock on every file it opens, unless `HDF5_USE_FILE_LOCKING=FALSE`.
fn locked_elsewhere(path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::io::AsRawFd;
        let Ok(file) = std::fs::File::open(path) else { return false };
        // SAFETY: flock on a descriptor this function owns; the lock, if taken, goes with it.
        let taken = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
        taken != 0 && std::io::Error::last_os_error().raw_os_error() == Some(libc::EWOULDBLOCK)
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        false
    }
}

/// Keeps the file's descriptor out of programs this process starts. HDF5 locks the files it
/// writes (flock) and opens them without close-on-exec: a child started while a file is open
/// (a test running a reader, a batch starting a run) would inherit the lock and keep it after this
/// process closed the file, and a reader opening the finished file, or this process opening it
/// again to resume, would find it locked.
fn close_on_exec(file: &File) {
    #[cfg(unix)]
    {
        let id = file.id();
        let mut handle: *mut std::ffi::c_void = std::ptr::null_mut();
        // SAFETY: HDF5 calls go through hdf5-metno's global lock, as its own do; with the default
        // (sec2) driver the handle is a pointer to the file's descriptor, an int.
        let found = hdf5::sync::sync(|| unsafe {
            hdf5_sys::h5f::H5Fget_vfd_handle(id, hdf5_sys::h5p::H5P_DEFAULT, &mut handle)
        });
        if found >= 0 && !handle.is_null() {
            // SAFETY: `handle` points to the descriptor's int (above); fcntl only sets its flag.
            unsafe {
                let fd = *(handle as *const std::ffi::c_int);
                libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC);
            }
        }
    }
    #[cfg(not(unix))]
    let _ = file;
}

/// A group whose links keep their creation order (the reader lists blocks in that order).
fn ordered_group(parent: &Group, name: &str) -> hdf5::Result<Group> {
    use hdf5::plist::group_create::LinkCreationOrder;
    parent.create_group_builder().with_gcpl(|p| p.link_creation_order(LinkCreationOrder::Indexed)).create(name)
}

fn write_version_and_type(group: &Group, kind: &str) -> hdf5::Result<()> {
    group.new_attr::<i64>().shape(2).create("Version")?.write_raw(&VERSION)?;
    // Fixed-length ASCII, as VTK writes it (its reader does not take variable-length strings).
    match kind {
        "UnstructuredGrid" => {
            let text = FixedAscii::<16>::from_ascii(kind).map_err(|e| hdf5::Error::from(e.to_string()))?;
            group.new_attr::<FixedAscii<16>>().create("Type")?.write_scalar(&text)
        }
        _ => {
            let text = FixedAscii::<28>::from_ascii(kind).map_err(|e| hdf5::Error::from(e.to_string()))?;
            group.new_attr::<FixedAscii<28>>().create("Type")?.write_scalar(&text)
        }
    }
}

/// A dataset of rows of `columns` values (1: a plain list), empty and growable. Uncompressed:
/// appending a frame rewrites the chunk that holds the end of the frame before, and a compressed
/// chunk is rewritten whole, so a run killed during that write lost frames it had written
/// (`inflate() failed` on resume); a plain chunk is rewritten with the same bytes where it holds
/// earlier frames.
fn growable<T: H5Type>(group: &Group, name: &str, columns: usize, chunk_rows: usize) -> hdf5::Result<Dataset> {
    if columns == 1 {
        group.new_dataset::<T>().shape(0..).chunk(chunk_rows).create(name)
    } else {
        group.new_dataset::<T>().shape((0.., columns)).chunk((chunk_rows, columns)).create(name)
    }
}

/// The per-frame counts of a block, one row a frame.
const COUNTS: [&str; 3] = ["NumberOfPoints", "NumberOfCells", "NumberOfConnectivityIds"];
/// The read offsets of a block's `Steps`, one row a frame.
const STEP_LISTS: [&str; 6] =
    ["Values", "PartOffsets", "NumberOfParts", "PointOffsets", "CellOffsets", "ConnectivityIdOffsets"];

fn create_block(root: &Group, name: &str, index: i64) -> hdf5::Result<Group> {
    let block = root.create_group(name)?;
    write_version_and_type(&block, "UnstructuredGrid")?;
    block.new_attr::<i64>().create("Index")?.write_scalar(&index)?;
    for count in COUNTS {
        growable::<i64>(&block, count, 1, STEP_CHUNK_ROWS)?;
    }
    growable::<f64>(&block, "Points", 3, CHUNK_ROWS)?;
    growable::<i64>(&block, "Offsets", 1, CHUNK_ROWS)?;
    growable::<i64>(&block, "Connectivity", 1, CHUNK_ROWS)?;
    growable::<u8>(&block, "Types", 1, CHUNK_ROWS)?;
    block.create_group("PointData")?;
    block.create_group("CellData")?;
    let steps = block.create_group("Steps")?;
    steps.new_attr::<i64>().create("NSteps")?.write_scalar(&0i64)?;
    growable::<f64>(&steps, "Values", 1, STEP_CHUNK_ROWS)?;
    for list in &STEP_LISTS[1..] {
        growable::<i64>(&steps, list, 1, STEP_CHUNK_ROWS)?;
    }
    root.group("Assembly")?.link_soft(&format!("/VTKHDF/{name}"), name)?;
    Ok(block)
}

fn rows(dataset: &Dataset) -> usize {
    dataset.shape().first().copied().unwrap_or(0)
}

/// Appends `values` (rows of `columns`) to `dataset`, and writes them out of HDF5's chunk cache
/// at once. HDF5 1.10 drops a chunk it fails to write when it evicts it from the cache (a full
/// disk, a file-size limit) without an error, and a later file flush then succeeds: measured on a
/// full 2 MB tmpfs, a frame listed whole was read back as zeros. A dataset flush reports the
/// failed write instead.
fn append<T: H5Type>(dataset: &Dataset, values: &[T], columns: usize) -> hdf5::Result<()> {
    let start = rows(dataset);
    let added = values.len() / columns;
    if added == 0 {
        return Ok(());
    }
    let end = start + added;
    if columns == 1 && dataset.ndim() == 1 {
        dataset.resize(end)?;
        dataset.write_slice(ArrayView1::from(values), start..end)?;
    } else {
        dataset.resize((end, columns))?;
        let view = ArrayView2::from_shape((added, columns), values).map_err(|e| hdf5::Error::from(e.to_string()))?;
        dataset.write_slice(view, (start..end, 0..columns))?;
    }
    flush_dataset(dataset)
}

/// Writes a dataset's cached chunks to the file, or says why it could not.
fn flush_dataset(dataset: &Dataset) -> hdf5::Result<()> {
    // SAFETY: a valid dataset id; the call goes through hdf5-metno's lock, and its error stack is
    // read under it, as the crate's own calls do.
    hdf5::sync::sync(|| hdf5::h5check(unsafe { hdf5_sys::h5d::H5Dflush(dataset.id()) }))
        .map(|_| ())
        .map_err(|e| hdf5::Error::from(format!("writing `{}`: {}", dataset.name(), system_cause(&e.to_string()))))
}

/// The system's reason in an HDF5 error of a failed write (`..., errno = 28, error message = 'No
/// space left on device', ...`), or the error's first line.
fn system_cause(message: &str) -> String {
    let quoted = message.split("error message = '").nth(1).and_then(|rest| rest.split('\'').next());
    match (quoted, message.split("errno = ").nth(1).and_then(|rest| rest.split(',').next())) {
        (Some(why), Some(errno)) => format!("{why} (os error {errno})"),
        (Some(why), None) => why.to_string(),
        _ => message.lines().next().unwrap_or(message).to_string(),
    }
}

/// What a block held before a frame was appended (its frame count and the rows of its points,
/// cells and connectivity, which the frame's offsets in `Steps` name), and the frame's own counts
/// of points, cells and connectivity ids.
struct BlockEnd {
    step: i64,
    point_rows: usize,
    cell_rows: usize,
    connectivity_rows: usize,
    counts: [usize; 3],
}

/// The first half of appending a frame (`None`: empty) to a block: its geometry and fields, the
/// bulk of the bytes. The frame is not listed yet: a write that fails here leaves the file's
/// frames as they were.
fn append_frame_data(block: &Group, frame: Option<&BlockFrame>) -> hdf5::Result<BlockEnd> {
    let empty = BlockFrame::points(&[], &[]);
    let frame = frame.unwrap_or(&empty);
    let (cell_types, offsets, ids) = frame.cells();
    let end = BlockEnd {
        step: rows(&block.dataset("NumberOfPoints")?) as i64,
        point_rows: rows(&block.dataset("Points")?),
        cell_rows: rows(&block.dataset("Types")?),
        connectivity_rows: rows(&block.dataset("Connectivity")?),
        counts: [frame.points.len(), cell_types.len(), ids.len()],
    };
    let flat: Vec<f64> = frame.points.iter().flatten().copied().collect();
    append(&block.dataset("Points")?, &flat, 3)?;
    append(&block.dataset("Offsets")?, &offsets, 1)?;
    append(&block.dataset("Connectivity")?, &ids, 1)?;
    append(&block.dataset("Types")?, &cell_types, 1)?;
    append_fields(&block.group("PointData")?, frame.point_fields, end.point_rows, frame.points.len())?;
    append_fields(&block.group("CellData")?, frame.cell_fields, end.cell_rows, cell_types.len())?;
    Ok(end)
}

/// The second half: the frame's counts and its row of offsets in `Steps`, which list it, the
/// frame count `NSteps` last.
fn list_frame(block: &Group, time: f64, end: &BlockEnd) -> hdf5::Result<()> {
    for (count, value) in COUNTS.iter().zip(end.counts) {
        append(&block.dataset(count)?, &[value as i64], 1)?;
    }
    let steps = block.group("Steps")?;
    let next = [end.step, 1, end.point_rows as i64, end.cell_rows as i64, end.connectivity_rows as i64];
    append(&steps.dataset("Values")?, &[time], 1)?;
    for (list, value) in STEP_LISTS[1..].iter().zip(next) {
        append(&steps.dataset(list)?, &[value], 1)?;
    }
    steps.attr("NSteps")?.write_scalar(&(end.step + 1))
}

/// Appends one frame (`None`: empty) to a block, data first, listing last.
fn append_frame(block: &Group, time: f64, frame: Option<&BlockFrame>) -> hdf5::Result<()> {
    let end = append_frame_data(block, frame)?;
    list_frame(block, time, &end)
}

/// Appends this frame's `fields` (`count` rows each) to the arrays of `group`, which hold `before`
/// rows each. A field new to the file starts with zeros for the frames before; an array this frame
/// lacks gets zeros.
fn append_fields(group: &Group, fields: &[Field], before: usize, count: usize) -> hdf5::Result<()> {
    let mut written = Vec::new();
    for field in fields {
        let name = array_name(&field.name);
        let columns = field.components;
        let dataset = match group.dataset(&name) {
            Ok(d) => d,
            Err(_) => {
                let d = if field.integer {
                    growable::<i64>(group, &name, columns, CHUNK_ROWS)?
                } else {
                    growable::<f64>(group, &name, columns, CHUNK_ROWS)?
                };
                pad(&d, before)?;
                d
            }
        };
        let existing_columns = dataset.shape().get(1).copied().unwrap_or(1);
        if existing_columns != columns {
            return Err(hdf5::Error::from(format!(
                "array `{name}` has {existing_columns} components in earlier frames and {columns} in this one"
            )));
        }
        if dataset.dtype()?.is::<i64>() {
            let values: Vec<i64> = field.values.iter().map(|&v| v as i64).collect();
            append(&dataset, &values, columns)?;
        } else {
            append(&dataset, &field.values, columns)?;
        }
        written.push(name);
    }
    for name in group.member_names()? {
        if !written.contains(&name) {
            pad(&group.dataset(&name)?, count)?;
        }
    }
    Ok(())
}

/// Appends `count` rows of zeros.
fn pad(dataset: &Dataset, count: usize) -> hdf5::Result<()> {
    let columns = dataset.shape().get(1).copied().unwrap_or(1);
    if dataset.dtype()?.is::<i64>() {
        append(dataset, &vec![0i64; count * columns], columns)
    } else {
        append(dataset, &vec![0f64; count * columns], columns)
    }
}

/// Shrinks a dataset to `rows` rows.
fn shrink(dataset: &Dataset, rows: usize) -> hdf5::Result<()> {
    match dataset.shape().get(1) {
        Some(&columns) => dataset.resize((rows, columns)),
        None => dataset.resize(rows),
    }
}

/// How many frames a block holds whole: listed in every row list of `Steps` and in the counts, and
/// with all their rows in the arrays.
fn whole_frames(block: &Group) -> hdf5::Result<usize> {
    let held = |frames: usize| -> hdf5::Result<bool> {
        for (path, needed) in kept_rows(block, frames)? {
            if rows(&block.dataset(&path)?) < needed {
                return Ok(false);
            }
        }
        Ok(true)
    };
    let mut frames = rows(&block.dataset("Steps/Values")?);
    while frames > 0 && !held(frames)? {
        frames -= 1;
    }
    Ok(frames)
}

/// Keeps the first `keep` frames of a block.
fn truncate_block(block: &Group, keep: usize) -> hdf5::Result<()> {
    for (path, rows) in kept_rows(block, keep)? {
        shrink(&block.dataset(&path)?, rows)?;
    }
    block.group("Steps")?.attr("NSteps")?.write_scalar(&(keep as i64))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn dir() -> PathBuf {
        let dir = std::env::temp_dir().join(format!("granite_vtkhdf_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A frame of `n` points (ids from `first`, a 6-component tensor) and, when `walls`, two
    /// polygons and `n - 2` lines over four corners.
    fn frame(n: usize, first: i64) -> (Vec<Vec3>, Vec<Field>, PolyData) {
        let x = (0..n).map(|i| [i as f64, first as f64, 0.5]).collect();
        let fields = vec![
            Field::int("id", (0..n as i64).map(|i| first + i)),
            Field::float("stress", 6, (0..6 * n).map(|v| v as f64 * 0.25 - first as f64).collect()),
        ];
        let lines = n.saturating_sub(2);
        let walls = PolyData {
            points: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            lines: (0..lines as u32).map(|i| [0, 1 + i % 3]).collect(),
            polygons: vec![vec![0, 1, 2], vec![0, 2, 3, 1]],
            point_fields: Vec::new(),
            cell_fields: vec![Field::float("force", 1, (0..lines + 2).map(|v| v as f64 + first as f64).collect())],
        };
        (x, fields, walls)
    }

    /// Every dataset of the file by path, its values as f64 (ints and bytes are small here).
    fn datasets(path: &Path) -> BTreeMap<String, Vec<f64>> {
        fn walk(group: &Group, prefix: &str, out: &mut BTreeMap<String, Vec<f64>>) {
            for name in group.member_names().unwrap() {
                let path = format!("{prefix}/{name}");
                if let Ok(sub) = group.group(&name) {
                    walk(&sub, &path, out);
                } else if let Ok(d) = group.dataset(&name) {
                    let values = if d.dtype().unwrap().is::<f64>() {
                        d.read_raw::<f64>().unwrap()
                    } else if d.dtype().unwrap().is::<u8>() {
                        d.read_raw::<u8>().unwrap().into_iter().map(f64::from).collect()
                    } else {
                        d.read_raw::<i64>().unwrap().into_iter().map(|v| v as f64).collect()
                    };
                    out.insert(path, values);
                }
            }
        }
        let file = File::open(path).unwrap();
        let mut out = BTreeMap::new();
        walk(&file.group("VTKHDF/points").unwrap(), "points", &mut out);
        if let Ok(walls) = file.group("VTKHDF/walls") {
            walk(&walls, "walls", &mut out);
        }
        out
    }

    #[test]
    fn a_block_seen_late_or_missing_gets_empty_frames_and_arrays_stay_aligned() {
        let path = dir().join("late.vtkhdf");
        let mut writer = VtkHdfWriter::create(&path).unwrap();
        let (x0, f0, _) = frame(3, 0);
        writer.write_frame(0.0, &[("points", BlockFrame::points(&x0, &f0))]).unwrap();
        let (x1, mut f1, w1) = frame(5, 10);
        f1.push(Field::float("damage", 1, vec![0.5; 5]));
        let frame1 = [("points", BlockFrame::points(&x1, &f1)), ("walls", BlockFrame::poly(&w1))];
        writer.write_frame(0.5, &frame1).unwrap();
        let (x2, f2, _) = frame(2, 20);
        writer.write_frame(1.0, &[("points", BlockFrame::points(&x2, &f2))]).unwrap();
        drop(writer);
        let d = datasets(&path);
        assert_eq!(d["points/NumberOfPoints"], [3.0, 5.0, 2.0]);
        assert_eq!(d["walls/NumberOfPoints"], [0.0, 4.0, 0.0]);
        assert_eq!(d["walls/NumberOfCells"], [0.0, 5.0, 0.0], "3 lines and 2 polygons in frame 1");
        assert_eq!(d["walls/Types"], [3.0, 3.0, 3.0, 7.0, 7.0]);
        assert_eq!(d["walls/Steps/Values"], d["points/Steps/Values"]);
        assert_eq!(d["points/Steps/Values"], [0.0, 0.5, 1.0]);
        // Offsets: one more than the cells in every frame, cells counted before each frame.
        assert_eq!(d["points/Offsets"].len(), 10 + 3);
        assert_eq!(d["points/Steps/CellOffsets"], [0.0, 3.0, 8.0]);
        assert_eq!(d["points/Steps/PartOffsets"], [0.0, 1.0, 2.0]);
        // A field first seen in frame 1 has zeros for frames 0 and 2.
        let damage = &d["points/PointData/damage"];
        assert_eq!(damage.len(), 10);
        assert_eq!(damage[..3], [0.0; 3]);
        assert_eq!(damage[3..8], [0.5; 5]);
        assert_eq!(damage[8..], [0.0; 2]);
        assert_eq!(d["points/PointData/stress"].len(), 6 * 10);
        assert_eq!(d["walls/CellData/force"], [10.0, 11.0, 12.0, 13.0, 14.0]);
        let nsteps: i64 = File::open(&path)
            .unwrap()
            .group("VTKHDF/walls/Steps")
            .unwrap()
            .attr("NSteps")
            .unwrap()
            .read_scalar()
            .unwrap();
        assert_eq!(nsteps, 3);
    }

    #[test]
    fn a_frame_at_an_earlier_time_replaces_the_later_frames_and_a_resume_keeps_the_earlier_ones() {
        let frames: Vec<_> = [(4, 0), (6, 10), (3, 20), (5, 30)].iter().map(|&(n, first)| frame(n, first)).collect();
        let write = |writer: &mut VtkHdfWriter, time: f64, k: usize| {
            let (x, f, w) = &frames[k];
            writer.write_frame(time, &[("points", BlockFrame::points(x, f)), ("walls", BlockFrame::poly(w))]).unwrap();
        };
        let straight = dir().join("straight.vtkhdf");
        let mut writer = VtkHdfWriter::create(&straight).unwrap();
        write(&mut writer, 0.0, 0);
        write(&mut writer, 1.0, 1);
        write(&mut writer, 2.0, 3);
        drop(writer);

        // Frames at 0, 1, 2 and 3, then again at 2: the frames at 2 and 3 are replaced.
        let rewritten = dir().join("rewritten.vtkhdf");
        let mut writer = VtkHdfWriter::create(&rewritten).unwrap();
        for k in 0..3 {
            write(&mut writer, k as f64, k);
        }
        write(&mut writer, 3.0, 0);
        write(&mut writer, 2.0, 3);
        assert_eq!(writer.frames(), 3);
        drop(writer);
        assert_eq!(datasets(&straight), datasets(&rewritten));

        // A run resumed at t = 2 keeps the frames at 0 and 1 and writes on after them.
        let resumed = dir().join("resumed.vtkhdf");
        let mut writer = VtkHdfWriter::create(&resumed).unwrap();
        for k in 0..4 {
            write(&mut writer, k as f64, k);
        }
        drop(writer);
        let mut writer = VtkHdfWriter::resume(&resumed, 2.0).unwrap();
        assert_eq!(writer.frames(), 2);
        write(&mut writer, 2.0, 3);
        drop(writer);
        assert_eq!(datasets(&straight), datasets(&resumed));
    }

    #[test]
    fn a_frame_cut_short_by_a_kill_is_dropped_on_resume() {
        let (x, f, w) = frame(4, 0);
        let blocks = [("points", BlockFrame::points(&x, &f)), ("walls", BlockFrame::poly(&w))];
        let whole = dir().join("whole.vtkhdf");
        let mut writer = VtkHdfWriter::create(&whole).unwrap();
        writer.write_frame(0.0, &blocks).unwrap();
        writer.write_frame(1.0, &blocks).unwrap();
        drop(writer);
        let cut = dir().join("cut.vtkhdf");
        std::fs::copy(&whole, &cut).unwrap();
        // A third frame stopped part way: the points block has its time, count and points, the
        // walls block nothing yet.
        {
            let file = File::open_rw(&cut).unwrap();
            let points = file.group("VTKHDF/points").unwrap();
            append(&points.dataset("Steps/Values").unwrap(), &[2.0], 1).unwrap();
            append(&points.dataset("NumberOfPoints").unwrap(), &[4i64], 1).unwrap();
            let flat: Vec<f64> = x.iter().flatten().copied().collect();
            append(&points.dataset("Points").unwrap(), &flat, 3).unwrap();
        }
        let writer = VtkHdfWriter::resume(&cut, 5.0).unwrap();
        assert_eq!(writer.frames(), 2);
        drop(writer);
        assert_eq!(datasets(&whole), datasets(&cut));
    }

    /// Programs this process starts do not inherit the open file (nor HDF5's lock on it).
    #[cfg(target_os = "linux")]
    #[test]
    fn the_open_file_is_closed_on_exec() {
        let path = dir().join("cloexec.vtkhdf");
        let writer = VtkHdfWriter::create(&path).unwrap();
        let target = std::fs::canonicalize(&path).unwrap();
        let mut descriptors = 0;
        for entry in std::fs::read_dir("/proc/self/fd").unwrap().flatten() {
            if std::fs::read_link(entry.path()).is_ok_and(|p| p == target) {
                let fd: i32 = entry.file_name().to_string_lossy().parse().unwrap();
                // SAFETY: reads the flags of a descriptor this process holds.
                let flags = unsafe { libc::fcntl(fd, libc::F_GETFD) };
                assert!(flags & libc::FD_CLOEXEC != 0, "descriptor {fd} of the file is inherited by children");
                descriptors += 1;
            }
        }
        assert!(descriptors >= 1);
        drop(writer);
    }

    #[test]
    fn a_file_that_cannot_be_read_is_set_aside_on_resume() {
        let path = dir().join("damaged.vtkhdf");
        std::fs::write(&path, b"not an HDF5 file").unwrap();
        let mut writer = VtkHdfWriter::resume(&path, 1.0).unwrap();
        assert_eq!(writer.frames(), 0);
        assert_eq!(std::fs::read(path.with_extension("vtkhdf.damaged")).unwrap(), b"not an HDF5 file");
        let note = writer.take_note().unwrap();
        assert!(note.contains("could not be continued") && note.contains("damaged.vtkhdf.damaged"), "{note}");
        // A file cut short (a file-size limit): set aside with HDF5's reason, not taken for a
        // file another program holds.
        let cut = dir().join("cut.vtkhdf");
        let mut full = VtkHdfWriter::create(&cut).unwrap();
        let (x, fields, _) = frame(50, 0);
        full.write_frame(0.0, &[("points", BlockFrame::points(&x, &fields))]).unwrap();
        drop(full);
        let bytes = std::fs::read(&cut).unwrap();
        std::fs::write(&cut, &bytes[..bytes.len() / 3]).unwrap();
        let mut writer = VtkHdfWriter::resume(&cut, 1.0).unwrap();
        assert_eq!(writer.frames(), 0);
        let note = writer.take_note().unwrap();
        assert!(!note.contains("another program") && note.contains("cut.vtkhdf.damaged"), "{note}");
        drop(writer);
        // A file another program holds (HDF5's lock, as a reader takes it) is left alone.
        #[cfg(unix)]
        {
            use std::os::unix::io::AsRawFd;
            let reader = std::fs::File::open(&cut).unwrap();
            // SAFETY: a shared lock on a descriptor this test holds.
            assert_eq!(unsafe { libc::flock(reader.as_raw_fd(), libc::LOCK_SH | libc::LOCK_NB) }, 0);
            let e = VtkHdfWriter::resume(&cut, 1.0).err().unwrap().to_string();
            assert!(e.contains("open in another program"), "{e}");
            assert!(cut.is_file());
        }
        // A missing file starts a new series.
        let fresh = dir().join("missing.vtkhdf");
        let _ = std::fs::remove_file(&fresh);
        assert_eq!(VtkHdfWriter::resume(&fresh, 1.0).unwrap().frames(), 0);
        assert!(fresh.is_file());
    }
}
