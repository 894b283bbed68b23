//! Uploads in bounded pieces. `queue.write_buffer` keeps a staging copy of what it writes until
//! the submission that carries it has run, so a scene written in one go is held twice while it
//! uploads (on a software adapter both copies are the process's memory, and the driver's
//! allocator keeps the staging blocks for reuse). Natively, an [`Uploader`] submits and waits
//! each time its writes since the last wait pass [`UPLOAD_PIECE_BYTES`], so staging never holds
//! more than about that much. A browser cannot block on the queue and stages in its own process:
//! there it writes straight through.

use crate::error::Result;
use crate::gpu::Gpu;

/// Staging held at most between two waits, natively. One piece of a tile's surfels
/// (scene/surfels.rs): the driver's allocator keeps a freed staging block for the next, so twice
/// this is what staging costs at a change of tiles (heaptrack of `grotto view` under
/// `--gpu-memory 256M`: 33.5 MB of staging at its peak with 16 MiB, docs/benchmarks.md).
pub(crate) const UPLOAD_PIECE_BYTES: usize = 8 << 20;

/// Writes into buffers, waiting for the queue every [`UPLOAD_PIECE_BYTES`].
#[derive(Debug)]
pub(crate) struct Uploader<'g> {
    gpu: &'g Gpu,
    pending: usize,
    /// Bytes written in all.
    pub(crate) written: u64,
}

impl<'g> Uploader<'g> {
    pub(crate) fn new(gpu: &'g Gpu) -> Self {
        Self { gpu, pending: 0, written: 0 }
    }

    /// Writes `bytes` at `offset` of `buffer` (both multiples of 4, as `write_buffer` wants);
    /// returns how many bytes that was.
    pub(crate) fn write(&mut self, buffer: &wgpu::Buffer, offset: u64, bytes: &[u8]) -> Result<u64> {
        let mut at = offset;
        for piece in bytes.chunks(UPLOAD_PIECE_BYTES) {
            // Waited for before a piece that would take staging past the bound, not after: writes
            // a little under the bound each would otherwise hold two pieces' staging at once.
            if self.pending + piece.len() > UPLOAD_PIECE_BYTES && !cfg!(target_arch = "wasm32") {
                self.flush()?;
            }
            self.gpu.queue.write_buffer(buffer, at, piece);
            at += piece.len() as u64;
            self.pending += piece.len();
        }
        self.written += bytes.len() as u64;
        Ok(bytes.len() as u64)
    }

    /// Submits what was written and waits for it, so its staging is freed.
    fn flush(&mut self) -> Result<()> {
        self.gpu.queue.submit([]);
        self.gpu.wait()?;
        self.pending = 0;
        Ok(())
    }
}

/// A move of `len` bytes within one buffer, from byte `from` to byte `to` (`to <= from`; all
/// three multiples of 4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Move {
    pub(crate) from: u64,
    pub(crate) to: u64,
    pub(crate) len: u64,
}

/// Moves ranges of `buffer` toward its start on the GPU (a pool compacted: render/pool.rs), with
/// nothing read back. A copy may not read and write one buffer, so each piece goes through a
/// scratch buffer of at most [`UPLOAD_PIECE_BYTES`]. Done in `moves`' order, front to back; that is
/// safe where each move goes toward the start and lands before the next move's source (a
/// compaction in the order the ranges lay), because a piece then only overwrites bytes already
/// read: anything else is refused before a copy is made. Returns the bytes moved.
pub(crate) fn move_within(gpu: &Gpu, buffer: &wgpu::Buffer, moves: &[Move]) -> Result<u64> {
    let bad = |why: String| crate::error::Error::Internal { what: "GPU move", message: why };
    for (k, m) in moves.iter().enumerate() {
        if m.to > m.from || (m.from | m.to | m.len) % 4 != 0 || m.from + m.len > buffer.size() {
            return Err(bad(format!("{m:?} does not move toward the start within {} bytes", buffer.size())));
        }
        if let Some(next) = moves.get(k + 1)
            && (next.from < m.from + m.len || m.to + m.len > next.from)
        {
            return Err(bad(format!("{m:?} then {next:?} are not in the order they lay")));
        }
    }
    let largest = moves.iter().filter(|m| m.to != m.from).map(|m| m.len).max().unwrap_or(0);
    if largest == 0 {
        return Ok(0);
    }
    let piece = largest.min(UPLOAD_PIECE_BYTES as u64);
    let scratch =
        gpu.buffer("move scratch", piece, wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST)?;
    let mut enc = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("move") });
    let mut moved = 0;
    for m in moves.iter().filter(|m| m.to != m.from) {
        let mut done = 0;
        while done < m.len {
            let n = (m.len - done).min(piece);
            enc.copy_buffer_to_buffer(buffer, m.from + done, &scratch, 0, n);
            enc.copy_buffer_to_buffer(&scratch, 0, buffer, m.to + done, n);
            done += n;
        }
        moved += m.len;
    }
    gpu.queue.submit([enc.finish()]);
    Ok(moved)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::GpuOptions;

    fn scratch_of(gpu: &Gpu, bytes: usize) -> wgpu::Buffer {
        gpu.buffer("upload scratch", bytes as u64, wgpu::BufferUsages::COPY_DST).unwrap()
    }

    #[test]
    fn writes_larger_than_a_piece_arrive_whole_and_in_place() {
        let opts = GpuOptions {
            prefer_software: true,
            backends: Some(wgpu::Backends::VULKAN),
            ..Default::default()
        };
        let gpu = Gpu::new(&opts).unwrap();
        let words = (UPLOAD_PIECE_BYTES * 5 / 2) / 4;
        let data: Vec<u32> = (0..words as u32).map(|i| i.wrapping_mul(2_654_435_761)).collect();
        let usage = wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let size = 8 + 4 * words as u64 + 12;
        let buffer = gpu.buffer("upload test", size, usage).unwrap();
        let mut up = Uploader::new(&gpu);
        assert_eq!(up.write(&buffer, 8, bytemuck::cast_slice(&data)).unwrap(), 4 * words as u64);
        assert!(up.pending <= UPLOAD_PIECE_BYTES, "the queue was waited on between pieces");
        // Writes each a little under the bound are waited for one by one.
        let mut apart = Uploader::new(&gpu);
        let under = vec![0u8; UPLOAD_PIECE_BYTES - 64];
        for k in 0..3 {
            apart.write(&scratch_of(&gpu, under.len()), 0, &under).unwrap();
            assert_eq!(apart.pending, under.len(), "write {k}: no two writes' staging held at once");
        }
        up.write(&buffer, 8 + 4 * words as u64, bytemuck::cast_slice(&[7u32, 8, 9])).unwrap();
        assert_eq!(up.written, 4 * words as u64 + 12);
        gpu.queue.submit([]);
        let back: Vec<u32> = bytemuck::pod_collect_to_vec(&gpu.read_buffer(&buffer, size).unwrap());
        assert_eq!(&back[2..2 + words], &data[..], "the pieces land where the whole would");
        assert_eq!(&back[2 + words..], &[7, 8, 9]);

        // Compacted toward the start: overlapping moves of more than a piece, front to back.
        let (a, b) = (4 * 1000u64, 4 * (words as u64 / 2));
        let moves = [Move { from: 8, to: 0, len: a }, Move { from: 8 + a + 64, to: a, len: b }];
        assert_eq!(move_within(&gpu, &buffer, &moves).unwrap(), a + b);
        let moved: Vec<u32> = bytemuck::pod_collect_to_vec(&gpu.read_buffer(&buffer, size).unwrap());
        let (a, b) = (a as usize / 4, b as usize / 4);
        assert_eq!(&moved[..a], &data[..a], "the first range moved whole");
        assert_eq!(&moved[a..a + b], &data[a + 16..a + 16 + b], "the second, over its own old place");
        let backwards = [Move { from: 0, to: 8, len: 16 }];
        assert!(move_within(&gpu, &buffer, &backwards).is_err(), "a move away from the start is refused");
        let crossing = [Move { from: 64, to: 0, len: 64 }, Move { from: 32, to: 16, len: 8 }];
        assert!(move_within(&gpu, &buffer, &crossing).is_err(), "moves out of order are refused");
    }
}
