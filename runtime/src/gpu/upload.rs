//! Uploads in bounded pieces. `queue.write_buffer` keeps a staging copy of what it writes until
//! the submission that carries it has run, so a scene written in one go is held twice while it
//! uploads (on a software adapter both copies are the process's memory, and the driver's
//! allocator keeps the staging blocks for reuse). Natively, an [`Uploader`] submits and waits
//! each time its writes since the last wait pass [`UPLOAD_PIECE_BYTES`], so staging never holds
//! more than about that much. A browser cannot block on the queue and stages in its own process:
//! there it writes straight through.

use crate::error::Result;
use crate::gpu::Gpu;

/// Staging held at most between two waits, natively.
pub(crate) const UPLOAD_PIECE_BYTES: usize = 16 << 20;

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
            self.gpu.queue.write_buffer(buffer, at, piece);
            at += piece.len() as u64;
            self.pending += piece.len();
            if self.pending >= UPLOAD_PIECE_BYTES && !cfg!(target_arch = "wasm32") {
                self.flush()?;
            }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::GpuOptions;

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
        assert!(up.pending < UPLOAD_PIECE_BYTES, "the queue was waited on between pieces");
        up.write(&buffer, 8 + 4 * words as u64, bytemuck::cast_slice(&[7u32, 8, 9])).unwrap();
        assert_eq!(up.written, 4 * words as u64 + 12);
        gpu.queue.submit([]);
        let back: Vec<u32> = bytemuck::pod_collect_to_vec(&gpu.read_buffer(&buffer, size).unwrap());
        assert_eq!(&back[2..2 + words], &data[..], "the pieces land where the whole would");
        assert_eq!(&back[2 + words..], &[7, 8, 9]);
    }
}
