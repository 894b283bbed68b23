//! One memory budget for a viewer (`grotto render|view --memory`, the page's `budget=`): a named
//! size or a number of bytes for the viewer's own memory (a page's wasm memory) and the GPU's
//! together, and what each part of the viewer may take of it.
//!
//! The split: half for the GPU, half for the process (a page's wasm memory; natively the heap,
//! the driver and the package's mapped pages). Of the GPU's half, the shadow atlas takes at most a
//! quarter (the preset's maps for fewer lights first, then smaller maps), the render targets at
//! most an eighth (a page draws smaller where they would take more), an eighth (at least 64 MiB,
//! where that is at most a quarter) stays for what no knob sizes (lookups, lights, the
//! environment atlas, the repack scratch) and the tile pools
//! take the rest. On a phone, and on a software adapter, the GPU's bytes are the process's, so
//! the budget bounds the whole; elsewhere it is what the viewer asks of each memory.

use serde::{Deserialize, Serialize};

use crate::settings::Settings;

/// WebGPU's default largest storage-buffer binding, which every browser grants unasked.
pub const WEBGPU_DEFAULT_BINDING_BYTES: u64 = 128 << 20;
/// GPU bytes a pixel of the image takes at most: the G-buffer's 16, the shaded frame's 16 and the
/// still frame's sample sums' 32 (render/targets.rs).
pub const TARGET_BYTES_PER_PIXEL: u64 = 64;
/// Bytes a texel of the shadow atlas takes (passes/shadow.rs `DISTANCE_FORMAT`, and a face of
/// depth).
const ATLAS_TEXEL_BYTES: u64 = 4;
/// Surfels drawn for each byte of the budget: one per 256 bytes, about 2 million on a phone (the
/// field's viewers draw 1 million by default) and none cut on a desktop's scene of 16 million.
const BYTES_PER_DRAWN_SURFEL: u64 = 256;
/// The smallest shadow face the budget shrinks maps to, and the fewest lights it keeps maps for
/// before it shrinks them.
const SMALLEST_FACE: u32 = 128;
/// The least kept of the GPU's share for what no knob sizes, where that is at most a quarter.
const UNSIZED_FLOOR_BYTES: u64 = 64 << 20;
const FEWEST_SHADOWED: u32 = 4;

/// Which budget: a named one, or bytes given.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BudgetName {
    Phone,
    Laptop,
    Desktop,
    Given,
}

impl BudgetName {
    /// The name a user gives (`None` for bytes given).
    pub fn as_str(self) -> Option<&'static str> {
        match self {
            Self::Phone => Some("phone"),
            Self::Laptop => Some("laptop"),
            Self::Desktop => Some("desktop"),
            Self::Given => None,
        }
    }
}

/// A viewer's memory budget: CPU and GPU together.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct MemoryBudget {
    pub name: BudgetName,
    pub total_bytes: u64,
}

/// What a page knows of its device (navigator.deviceMemory, touch, the screen) and its
/// adapter, from which it picks a budget.
#[derive(Clone, Copy, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceHints {
    /// `navigator.deviceMemory` in GB (Chromium's browsers; rounded, at most 8), where known.
    pub memory_gb: Option<f64>,
    /// The main pointer is a finger (`(pointer: coarse)`, or touch points).
    #[serde(default)]
    pub touch: bool,
    /// The screen's shorter side in CSS pixels.
    #[serde(default)]
    pub short_side_px: u32,
}

/// What a budget gives each part of a viewer.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MemoryPlan {
    pub budget: MemoryBudget,
    /// The process's share (a page's wasm memory).
    pub cpu_bytes: u64,
    /// The GPU's share, and what of it goes to the tile pools (`--gpu-memory`), the shadow atlas
    /// and the render targets.
    pub gpu_bytes: u64,
    pub pool_bytes: u64,
    pub atlas_bytes: u64,
    pub target_bytes: u64,
    /// Kept for what no knob sizes.
    pub reserve_bytes: u64,
    pub shadow_map_size: u32,
    pub shadowed_lights: u32,
    /// Most surfels drawn (`--point-budget`).
    pub points: u64,
    /// The image's pixels as asked, and the width and height scale that keeps its targets within
    /// their share (1: as asked).
    pub pixels: u64,
    pub pixel_scale: f32,
    /// Fetched package bytes a page keeps for revisits beyond what its tiles read (an eighth of
    /// the process's share), and tile bytes one streaming step fetches (a sixteenth).
    pub fetch_cache_bytes: u64,
    pub step_bytes: u64,
}

impl MemoryBudget {
    pub const PHONE: Self = Self { name: BudgetName::Phone, total_bytes: 512 << 20 };
    pub const LAPTOP: Self = Self { name: BudgetName::Laptop, total_bytes: 3 << 29 };
    pub const DESKTOP: Self = Self { name: BudgetName::Desktop, total_bytes: 4 << 30 };
    /// Below this no budget leaves the tile pools room: 64 MiB for the GPU's half.
    pub const SMALLEST_BYTES: u64 = 128 << 20;

    /// `phone`, `laptop`, `desktop`, or a size (`768M`, `2G`) of at least 128 MiB.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "phone" => Ok(Self::PHONE),
            "laptop" => Ok(Self::LAPTOP),
            "desktop" => Ok(Self::DESKTOP),
            other => {
                let total_bytes = grotto_format::parse_bytes(other)
                    .map_err(|e| format!("{e}; or name a budget: phone, laptop or desktop"))?;
                if total_bytes < Self::SMALLEST_BYTES {
                    return Err(format!(
                        "'{s}' is below the smallest memory budget, 128M (half for the GPU, and of that \
                         the tile pools need room)"
                    ));
                }
                Ok(Self { name: BudgetName::Given, total_bytes })
            }
        }
    }

    /// "phone (512 MiB)".
    pub fn describe(&self) -> String {
        let mib = self.total_bytes as f64 / f64::from(1u32 << 20);
        let size = if mib >= 1024.0 { format!("{:.1} GiB", mib / 1024.0) } else { format!("{mib:.0} MiB") };
        match self.name.as_str() {
            Some(name) => format!("{name} ({size})"),
            None => size,
        }
    }

    /// The budget for a device as a page sees it. A phone: a finger on a screen under 600 CSS
    /// pixels across, or 2 GB of memory or less. A desktop: 8 GB reported (Chromium reports at
    /// most 8) and no touch. Otherwise (a tablet, a smaller machine, a browser that does not say)
    /// a laptop.
    pub fn for_device(d: &DeviceHints) -> Self {
        let memory = d.memory_gb.filter(|g| g.is_finite() && *g > 0.0);
        let small_screen = d.touch && d.short_side_px > 0 && d.short_side_px < 600;
        if small_screen || memory.is_some_and(|g| g <= 2.0) {
            Self::PHONE
        } else if memory.is_some_and(|g| g >= 8.0) && !d.touch {
            Self::DESKTOP
        } else {
            Self::LAPTOP
        }
    }

    /// The plan for an image of `pixels` (width x height, supersampled) under `settings`' shadow
    /// maps: the atlas, the targets and the pools as the module's split gives them.
    pub fn plan(&self, pixels: u64, settings: &Settings) -> MemoryPlan {
        let gpu_bytes = self.total_bytes / 2;
        let cpu_bytes = self.total_bytes - gpu_bytes;
        let (shadow_map_size, shadowed_lights, atlas_bytes) = shadows_within(
            gpu_bytes / 4,
            if settings.shadows { settings.shadowed_lights } else { 0 },
            settings.shadow_map_size,
        );
        let target_share = gpu_bytes / 8;
        let wanted = pixels.saturating_mul(TARGET_BYTES_PER_PIXEL);
        let pixel_scale =
            if wanted > target_share { (target_share as f64 / wanted as f64).sqrt() as f32 } else { 1.0 };
        let target_bytes = wanted.min(target_share);
        // What no knob sizes (lookups, lights, the environment atlas, the repack scratch) took
        // 42 MiB on the 10^7-point cave at the phone's budget, over an eighth of its share.
        let reserve_bytes = (gpu_bytes / 8).max(UNSIZED_FLOOR_BYTES.min(gpu_bytes / 4));
        let pool_bytes = gpu_bytes - atlas_bytes - target_bytes - reserve_bytes;
        MemoryPlan {
            budget: *self,
            cpu_bytes,
            gpu_bytes,
            pool_bytes,
            atlas_bytes,
            target_bytes,
            reserve_bytes,
            shadow_map_size,
            shadowed_lights: if settings.shadows { shadowed_lights } else { settings.shadowed_lights },
            points: self.total_bytes / BYTES_PER_DRAWN_SURFEL,
            pixels,
            pixel_scale,
            fetch_cache_bytes: cpu_bytes / 8,
            step_bytes: cpu_bytes / 16,
        }
    }
}

impl MemoryPlan {
    /// `settings` with the plan's shadow maps (never larger or more than they were).
    pub fn apply(&self, settings: &mut Settings) {
        settings.shadow_map_size = settings.shadow_map_size.min(self.shadow_map_size);
        settings.shadowed_lights = settings.shadowed_lights.min(self.shadowed_lights);
    }

    /// This plan for an image drawn at the size asked (natively: an image is not drawn smaller
    /// than asked): what its targets take beyond their share comes out of the pools, which keep
    /// at least an eighth of the GPU's share.
    pub fn with_image_as_asked(self) -> Self {
        let wanted = self.pixels.saturating_mul(TARGET_BYTES_PER_PIXEL);
        let excess = wanted.saturating_sub(self.target_bytes);
        Self {
            target_bytes: wanted,
            pool_bytes: self.pool_bytes.saturating_sub(excess).max(self.gpu_bytes / 8),
            pixel_scale: 1.0,
            ..self
        }
    }

    /// The largest storage binding to ask a device for: WebGPU's default unless the pools are
    /// larger and the adapter offers more (`adapter_bytes`); the pools fit what it gives
    /// (`PoolCaps::within_binding`).
    pub fn storage_binding_bytes(&self, adapter_bytes: u64) -> u64 {
        self.pool_bytes.max(WEBGPU_DEFAULT_BINDING_BYTES).min(adapter_bytes.max(WEBGPU_DEFAULT_BINDING_BYTES))
    }

    /// One line for `--explain` and the page's panel.
    pub fn describe(&self) -> String {
        let mib = |b: u64| b as f64 / f64::from(1u32 << 20);
        format!(
            "memory budget {}: {:.0} MiB for the GPU (tile pools {:.0}, shadow atlas {:.0} for {} lights at {} px, \
             image {:.0}{}), {:.0} MiB for the viewer; at most {} surfels drawn",
            self.budget.describe(),
            mib(self.gpu_bytes),
            mib(self.pool_bytes),
            mib(self.atlas_bytes),
            self.shadowed_lights,
            self.shadow_map_size,
            mib(self.target_bytes),
            if self.pixel_scale < 1.0 { format!(" at {:.2} scale", self.pixel_scale) } else { String::new() },
            mib(self.cpu_bytes),
            self.points,
        )
    }
}

/// Shadow maps within `share` bytes: `lights` maps at `face` texels where they fit; else fewer
/// lights, down to [`FEWEST_SHADOWED`]; else smaller faces, down to [`SMALLEST_FACE`]; else fewer
/// lights still. Returns (face, lights, bytes).
fn shadows_within(share: u64, lights: u32, face: u32) -> (u32, u32, u64) {
    let bytes = |lights: u32, face: u32| atlas_bytes(6 * lights, face);
    if lights == 0 {
        return (face, 0, 0);
    }
    let mut face = face;
    let mut n = lights;
    while n > FEWEST_SHADOWED.min(lights) && bytes(n, face) > share {
        n -= 1;
    }
    while face > SMALLEST_FACE && bytes(n, face) > share {
        face /= 2;
    }
    while n > 1 && bytes(n, face) > share {
        n -= 1;
    }
    (face, n, bytes(n, face))
}

/// GPU bytes of a shadow atlas of `faces` faces of `face` texels: its near-square grid of faces
/// (passes/shadow.rs) and one face of depth.
pub fn atlas_bytes(faces: u32, face: u32) -> u64 {
    let (cols, rows) = crate::passes::shadow::atlas_grid(faces.max(1));
    let texels = u64::from(face) * u64::from(face);
    (u64::from(cols * rows) + 1) * texels * ATLAS_TEXEL_BYTES
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::Quality;

    #[test]
    fn budgets_parse_by_name_or_size_and_refuse_what_leaves_no_room() {
        assert_eq!(MemoryBudget::parse("phone"), Ok(MemoryBudget::PHONE));
        assert_eq!(MemoryBudget::parse(" Laptop "), Ok(MemoryBudget::LAPTOP));
        assert_eq!(MemoryBudget::parse("desktop").map(|b| b.total_bytes), Ok(4 << 30));
        assert_eq!(
            MemoryBudget::parse("768M"),
            Ok(MemoryBudget { name: BudgetName::Given, total_bytes: 768 << 20 })
        );
        for bad in ["64M", "tablet", "-1G", "NaN", ""] {
            assert!(MemoryBudget::parse(bad).is_err(), "{bad:?} was taken");
        }
        assert_eq!(MemoryBudget::PHONE.describe(), "phone (512 MiB)");
        assert_eq!(MemoryBudget::LAPTOP.describe(), "laptop (1.5 GiB)");
    }

    #[test]
    fn each_budget_splits_within_its_total_and_grows_with_it() {
        let settings = Settings::preset(Quality::Balanced);
        let mut last_pools = 0;
        for budget in [
            MemoryBudget::parse("128M").unwrap(),
            MemoryBudget::PHONE,
            MemoryBudget::LAPTOP,
            MemoryBudget::DESKTOP,
        ] {
            let p = budget.plan(1280 * 720, &settings);
            let gpu = p.pool_bytes + p.atlas_bytes + p.target_bytes + p.reserve_bytes;
            assert!(p.reserve_bytes >= p.gpu_bytes / 8 && p.reserve_bytes <= p.gpu_bytes / 4, "{p:?}");
            assert!(gpu <= p.gpu_bytes && p.gpu_bytes + p.cpu_bytes == budget.total_bytes, "{p:?}");
            assert!(p.atlas_bytes <= p.gpu_bytes / 4 && p.target_bytes <= p.gpu_bytes / 8, "{p:?}");
            assert_eq!(p.atlas_bytes, atlas_bytes(6 * p.shadowed_lights, p.shadow_map_size));
            assert!(p.pool_bytes > last_pools, "{p:?}");
            last_pools = p.pool_bytes;
            assert!(
                p.shadow_map_size <= settings.shadow_map_size
                    && p.shadowed_lights <= settings.shadowed_lights
            );
        }
        // A phone: fewer lights shadowed before smaller maps, its screen's image at full size,
        // and no binding asked for beyond what its pools could use or the adapter has.
        let phone = MemoryBudget::PHONE.plan(390 * 844, &settings);
        assert_eq!(phone.shadow_map_size, settings.shadow_map_size);
        assert!(phone.shadowed_lights < settings.shadowed_lights && phone.shadowed_lights >= FEWEST_SHADOWED);
        assert_eq!(phone.pixel_scale, 1.0);
        assert_eq!(phone.storage_binding_bytes(WEBGPU_DEFAULT_BINDING_BYTES), WEBGPU_DEFAULT_BINDING_BYTES);
        assert_eq!(phone.reserve_bytes, 64 << 20);
        assert!(phone.pool_bytes > 96 << 20 && phone.pool_bytes < 128 << 20, "{phone:?}");
        assert_eq!(phone.storage_binding_bytes(1 << 30), WEBGPU_DEFAULT_BINDING_BYTES);
        // A desktop keeps the preset's maps, and asks for a larger binding where the adapter has one.
        let desktop = MemoryBudget::DESKTOP.plan(1920 * 1080, &settings);
        assert_eq!((desktop.shadow_map_size, desktop.shadowed_lights), (512, settings.shadowed_lights));
        assert_eq!(desktop.storage_binding_bytes(1 << 30), 1 << 30);
        assert_eq!(desktop.storage_binding_bytes(64 << 20), WEBGPU_DEFAULT_BINDING_BYTES);
    }

    #[test]
    fn an_image_too_large_for_its_share_is_drawn_smaller_and_maps_shrink_last() {
        let settings = Settings::preset(Quality::High);
        // A phone's screen at pixel ratio 3: 1170 x 2532.
        let p = MemoryBudget::PHONE.plan(1170 * 2532, &settings);
        assert!(p.pixel_scale < 1.0);
        let scaled = (1170.0 * p.pixel_scale).floor() as u64 * (2532.0 * p.pixel_scale).floor() as u64;
        assert!(scaled * TARGET_BYTES_PER_PIXEL <= p.gpu_bytes / 8, "{p:?}");
        // 16 lights at 1024 px take 400 MiB: a phone keeps maps for its four brightest, smaller.
        assert_eq!(p.shadowed_lights, FEWEST_SHADOWED);
        assert!(p.shadow_map_size < 1024 && p.atlas_bytes <= p.gpu_bytes / 4, "{p:?}");
        let mut s = settings.clone();
        p.apply(&mut s);
        assert_eq!((s.shadow_map_size, s.shadowed_lights), (p.shadow_map_size, p.shadowed_lights));
        // Natively the image is drawn as asked: the pools pay for its targets.
        // On a phone's budget a 3-megapixel image leaves the pools their floor.
        let asked = p.with_image_as_asked();
        assert_eq!((asked.pixel_scale, asked.target_bytes), (1.0, 1170 * 2532 * TARGET_BYTES_PER_PIXEL));
        assert_eq!(asked.pool_bytes, p.gpu_bytes / 8);
        let laptop = MemoryBudget::LAPTOP.plan(1170 * 2532, &settings);
        let asked = laptop.with_image_as_asked();
        assert_eq!(asked.pool_bytes, laptop.pool_bytes - (asked.target_bytes - laptop.target_bytes));
        // No shadows asked: none planned, and the lights setting is left as it was.
        let off = Settings { shadows: false, ..settings.clone() };
        let p = MemoryBudget::PHONE.plan(640 * 480, &off);
        assert_eq!((p.atlas_bytes, p.shadowed_lights), (0, settings.shadowed_lights));
    }

    #[test]
    fn a_page_picks_its_budget_from_what_the_device_says() {
        let phone = DeviceHints { memory_gb: Some(8.0), touch: true, short_side_px: 390 };
        assert_eq!(MemoryBudget::for_device(&phone), MemoryBudget::PHONE);
        let small = DeviceHints { memory_gb: Some(2.0), touch: false, short_side_px: 1080 };
        assert_eq!(MemoryBudget::for_device(&small), MemoryBudget::PHONE);
        let tablet = DeviceHints { memory_gb: Some(8.0), touch: true, short_side_px: 820 };
        assert_eq!(MemoryBudget::for_device(&tablet), MemoryBudget::LAPTOP);
        let unknown = DeviceHints { memory_gb: None, touch: false, short_side_px: 1080 };
        assert_eq!(MemoryBudget::for_device(&unknown), MemoryBudget::LAPTOP);
        let desk = DeviceHints { memory_gb: Some(8.0), touch: false, short_side_px: 1440 };
        assert_eq!(MemoryBudget::for_device(&desk), MemoryBudget::DESKTOP);
        let nan = DeviceHints { memory_gb: Some(f64::NAN), ..desk };
        assert_eq!(MemoryBudget::for_device(&nan), MemoryBudget::LAPTOP);
    }
}
