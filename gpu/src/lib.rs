//! The RVEs of `dem_rve` on a GPU (`device: "gpu"`): wgpu over Vulkan, f64 WGSL compute
//! (`rve.wgsl`, with the contact law's own WGSL form). The RVEs of a material live in device
//! buffers split into sets within the adapter's binding limits; each MPM step is one submission
//! of one workgroup per RVE over every set, each workgroup running all of its RVE's DEM steps;
//! only the orders (velocity gradient, step counts) go up and the reports (stress, cell, counts)
//! come back. Everything else comes back only when asked for (checkpoints, outputs, a point's
//! object).

mod layout;

use granite_core::dem::{DemSim, Rve};
use granite_core::ext::{BatchCounters, RveBatch, RveDevice, RveOrder, RveReport};
use granite_core::{GraniteError, Result};
use layout::{Failure, Layout, Rec};
use std::sync::{Arc, OnceLock};
use wgpu::util::DeviceExt;

/// The GPU as an RVE device; the adapter is opened on first use.
#[derive(Default)]
pub struct GpuDevice {
    gpu: OnceLock<std::result::Result<Arc<Gpu>, String>>,
    /// Invocations per workgroup, when not chosen from the RVEs' size.
    workgroup: Option<u32>,
    /// Rebuild the candidate lists before every step (benchmarks).
    force_rebuild: bool,
    /// Most bytes of one bound buffer, below the adapter's own limit.
    max_binding: Option<u64>,
}

impl GpuDevice {
    pub fn new() -> GpuDevice {
        GpuDevice::default()
    }

    /// The device with workgroups of `size` invocations (64 to 1024, a power of two) whatever the
    /// RVEs' size.
    pub fn with_workgroup(size: u32) -> Result<GpuDevice> {
        if !WORKGROUP_SIZES.contains(&size) {
            return Err(GraniteError::Setup(format!("workgroup size {size}: one of {WORKGROUP_SIZES:?}")));
        }
        Ok(GpuDevice { workgroup: Some(size), ..Default::default() })
    }

    /// The device rebuilding every RVE's candidate lists before each DEM step, needed or not (a
    /// benchmark of the search; results stay those of a run that rebuilds when needed, to
    /// rounding).
    pub fn forcing_rebuilds(self) -> GpuDevice {
        GpuDevice { force_rebuild: true, ..self }
    }

    /// The device binding at most `bytes` bytes of a buffer at once (as `GRANITE_GPU_MAX_BINDING`
    /// does): a batch spreads over more buffer sets.
    pub fn with_max_binding(bytes: u64) -> GpuDevice {
        GpuDevice { max_binding: Some(bytes), ..Default::default() }
    }

    /// The adapter's name, driver and the limits that shape a batch (opening it if need be).
    pub fn adapter_facts(&self) -> Result<Vec<(String, String)>> {
        Ok(self.gpu()?.facts.clone())
    }

    fn gpu(&self) -> Result<Arc<Gpu>> {
        self.gpu.get_or_init(|| Gpu::start().map(Arc::new)).clone().map_err(GraniteError::Setup)
    }
}

impl RveDevice for GpuDevice {
    fn name(&self) -> &str {
        "gpu"
    }
    fn open(&self, rves: Vec<Rve>) -> Result<Box<dyn RveBatch>> {
        let gpu = self.gpu()?;
        let max_binding = self.max_binding.map_or(gpu.max_binding, |b| b.min(gpu.max_binding));
        let mut batch = GpuBatch {
            gpu,
            workgroup: self.workgroup,
            force_rebuild: self.force_rebuild,
            max_binding,
            counters: BatchCounters::default(),
            least_pairs: Vec::new(),
            shadows: Vec::new(),
            law: None,
            device: None,
            dirty: true,
        };
        batch.push(rves)?;
        Ok(Box::new(batch))
    }
}

/// An opened adapter with the compiled kernel.
pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// The kernel compiled for each workgroup size asked for so far.
    pipelines: std::sync::Mutex<std::collections::HashMap<(u32, &'static str), Arc<wgpu::ComputePipeline>>>,
    name: String,
    /// A software adapter (lavapipe): runs a workgroup's invocations on one CPU thread.
    software: bool,
    /// Most DEM steps, and most candidate-list rebuilds (0: any), of one dispatch. Mesa's
    /// software Vulkan (lavapipe) ends every loop of a kernel invocation after 65535 iterations in
    /// all, so there a call's steps go in short dispatches of one rebuild at most (with more, the
    /// column RVE's searches found fewer pairs: loops were cut); a GPU takes a whole MPM step's
    /// in one.
    chunk: u32,
    rebuilds: u32,
    /// Most bytes of one buffer bound to the kernel: the adapter's limits, or less by
    /// `GRANITE_GPU_MAX_BINDING`.
    max_binding: u64,
    /// Whether the adapter times its own work (timestamp queries).
    timestamps: bool,
    /// The adapter's name, driver and the limits that shape a batch, for `granite bench adapter`.
    facts: Vec<(String, String)>,
    /// Most invocations of one workgroup.
    max_invocations: u32,
}

/// The environment variable that lowers the largest buffer a set of RVEs binds (bytes).
pub const MAX_BINDING_VARIABLE: &str = "GRANITE_GPU_MAX_BINDING";

/// The adapter's largest binding, lowered by `GRANITE_GPU_MAX_BINDING` when set.
fn max_binding(limits: &wgpu::Limits) -> std::result::Result<u64, String> {
    let adapter = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    match std::env::var(MAX_BINDING_VARIABLE) {
        Err(_) => Ok(adapter),
        Ok(v) => match v.trim().parse::<u64>() {
            Ok(bytes) if bytes >= 1024 => Ok(bytes.min(adapter)),
            _ => Err(format!(
                "{MAX_BINDING_VARIABLE}={v}: a whole number of bytes, at least 1024 (the adapter binds at most {adapter})"
            )),
        },
    }
}

/// The adapter a process uses: under `mpirun`, the local rank's (round robin over the GPUs).
fn local_rank() -> usize {
    ["OMPI_COMM_WORLD_LOCAL_RANK", "MPI_LOCALRANKID", "SLURM_LOCALID", "PMI_LOCAL_RANK"]
        .iter()
        .find_map(|v| std::env::var(v).ok()?.parse().ok())
        .unwrap_or(0)
}

impl Gpu {
    fn start() -> std::result::Result<Gpu, String> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN,
            ..wgpu::InstanceDescriptor::new_without_display_handle_from_env()
        });
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN));
        let seen: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
        let mut usable: Vec<wgpu::Adapter> =
            adapters.into_iter().filter(|a| a.features().contains(wgpu::Features::SHADER_F64)).collect();
        // Real GPUs before software ones (lavapipe), each kind in the driver's order.
        usable.sort_by_key(|a| a.get_info().device_type == wgpu::DeviceType::Cpu);
        let real = usable.iter().filter(|a| a.get_info().device_type != wgpu::DeviceType::Cpu).count();
        let pool = if real > 0 { real } else { usable.len() };
        if pool == 0 {
            return Err(format!(
                "device \"gpu\": no Vulkan adapter with 64-bit float shaders (found: {}); install a Vulkan driver \
                 (a GPU's, or Mesa's software one: apt-get install mesa-vulkan-drivers)",
                if seen.is_empty() { "none".to_string() } else { seen.join(", ") }
            ));
        }
        let adapter = usable.swap_remove(local_rank() % pool);
        let name = adapter.get_info().name;
        let info = adapter.get_info();
        let limits = adapter.limits();
        let facts = vec![
            ("adapter".to_string(), name.clone()),
            ("driver".to_string(), format!("{} {}", info.driver, info.driver_info)),
            ("kind".to_string(), format!("{:?}", info.device_type)),
            ("max_storage_buffer_binding_size".to_string(), limits.max_storage_buffer_binding_size.to_string()),
            ("max_buffer_size".to_string(), limits.max_buffer_size.to_string()),
            ("max_compute_workgroup_storage_size".to_string(), limits.max_compute_workgroup_storage_size.to_string()),
            (
                "max_compute_invocations_per_workgroup".to_string(),
                limits.max_compute_invocations_per_workgroup.to_string(),
            ),
            (
                "max_compute_workgroups_per_dimension".to_string(),
                limits.max_compute_workgroups_per_dimension.to_string(),
            ),
            ("timestamp_query".to_string(), adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY).to_string()),
            ("adapters seen".to_string(), seen.join(", ")),
        ];
        let chunk = if adapter.get_info().device_type == wgpu::DeviceType::Cpu { 16 } else { 4096 };
        let max_binding = max_binding(&adapter.limits())?;
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let features = if timestamps {
            wgpu::Features::SHADER_F64 | wgpu::Features::TIMESTAMP_QUERY
        } else {
            wgpu::Features::SHADER_F64
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("granite RVEs"),
            required_features: features,
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| format!("device \"gpu\" ({name}): {e}"))?;
        let software = adapter.get_info().device_type == wgpu::DeviceType::Cpu;
        let rebuilds = if software { 1 } else { 0 };
        let gpu = Gpu {
            device,
            queue,
            pipelines: Default::default(),
            name,
            software,
            chunk,
            rebuilds,
            max_binding,
            timestamps,
            facts,
            max_invocations: limits.max_compute_invocations_per_workgroup,
        };
        Ok(gpu)
    }

    /// Invocations per workgroup for RVEs of `spheres` spheres: about one per 8 spheres on a GPU
    /// (occupancy: 400 RVEs of 2000 spheres are 400 workgroups), 64 on a software adapter.
    fn workgroup_size(&self, spheres: usize) -> u32 {
        if self.software {
            return WORKGROUP_SIZES[0];
        }
        WORKGROUP_SIZES
            .into_iter()
            .rev()
            .find(|&w| w <= LARGEST_CHOSEN && (w as usize) * 8 <= spheres)
            .unwrap_or(WORKGROUP_SIZES[0])
    }

    /// The kernel for workgroups of `size` invocations running the contact law `law` (its
    /// device form's WGSL).
    fn pipeline(&self, size: u32, law: &'static str) -> Result<Arc<wgpu::ComputePipeline>> {
        let mut pipelines = self.pipelines.lock().map_err(|_| GraniteError::Other("GPU pipelines poisoned".into()))?;
        if let Some(p) = pipelines.get(&(size, law)) {
            return Ok(p.clone());
        }
        if size > self.max_invocations {
            return Err(GraniteError::Setup(format!(
                "device \"gpu\" ({}): workgroups of {size} invocations, more than the adapter's {}",
                self.name, self.max_invocations
            )));
        }
        let kernel = include_str!("rve.wgsl").replace("const WG: u32 = 64u;", &format!("const WG: u32 = {size}u;"));
        let source = layout::wgsl_constants() + kernel.as_str() + "\n" + law;
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("rve.wgsl"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline = self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("run_rves"),
            layout: None,
            module: &module,
            entry_point: Some("run_rves"),
            compilation_options: Default::default(),
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GraniteError::Setup(format!(
                "device \"gpu\" ({}): the RVE kernel does not compile: {e}",
                self.name
            )));
        }
        let pipeline = Arc::new(pipeline);
        pipelines.insert((size, law), pipeline.clone());
        Ok(pipeline)
    }

    /// Copies `buffer` back to the host.
    fn read(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>> {
        let size = buffer.size();
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        self.map_and_read(&staging)
    }

    /// Waits for the queue and reads a mappable buffer.
    fn map_and_read(&self, staging: &wgpu::Buffer) -> Result<Vec<u8>> {
        let (tx, rx) = std::sync::mpsc::channel();
        staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            tx.send(r).ok();
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| gpu_error(&self.name, e))?;
        rx.recv().map_err(|e| gpu_error(&self.name, e))?.map_err(|e| gpu_error(&self.name, e))?;
        let bytes = staging.slice(..).get_mapped_range().map_err(|e| gpu_error(&self.name, e))?.to_vec();
        staging.unmap();
        Ok(bytes)
    }
}

fn gpu_error(name: &str, e: impl std::fmt::Display) -> GraniteError {
    GraniteError::Other(format!("device \"gpu\" ({name}): {e}"))
}

/// Times one call may give its RVEs more room for pairs.
const MOST_ROOM_GROWTHS: usize = 8;

/// Workgroup sizes the kernel is compiled for: up to 256 chosen by the RVEs' size, 512 and 1024
/// when asked for (`GpuDevice::with_workgroup`).
const WORKGROUP_SIZES: [u32; 5] = [64, 128, 256, 512, 1024];
/// The largest chosen without being asked for.
const LARGEST_CHOSEN: u32 = 256;

/// One set of device buffers (see `rve.wgsl` for their layout): consecutive RVEs of the batch,
/// as many as the adapter's binding limits allow in one set.
struct BufferSet {
    /// The batch's RVEs this set holds.
    range: std::ops::Range<usize>,
    layout: Layout,
    rve: wgpu::Buffer,
    sph: wgpu::Buffer,
    pf: wgpu::Buffer,
    ints: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// The set's RVE records as the last call left them.
    records: Vec<f64>,
    bytes: u64,
}

impl BufferSet {
    fn record(&mut self, r: usize) -> &mut [f64] {
        &mut self.records[r * layout::RVE_STRIDE..(r + 1) * layout::RVE_STRIDE]
    }
}

/// The batch on the device: its buffer sets, and where a call's records come back.
struct DeviceRves {
    pipeline: Arc<wgpu::ComputePipeline>,
    sets: Vec<BufferSet>,
    /// The records of every set, then the call's two timestamps: copied here at the end of each
    /// submission, read by the host.
    staging: wgpu::Buffer,
    timestamps: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    /// Whether the device holds a newer state than the host's copies.
    ahead: bool,
}

struct GpuBatch {
    gpu: Arc<Gpu>,
    workgroup: Option<u32>,
    force_rebuild: bool,
    /// Most bytes of one bound buffer.
    max_binding: u64,
    /// Per RVE, the fewest pair places to lay out for it (twice what its lists last needed
    /// when they outgrew their room; 0 until then).
    least_pairs: Vec<usize>,
    /// The RVEs as last brought to the host (the device may be ahead).
    shadows: Vec<DemSim>,
    law: Option<layout::LawConstants>,
    device: Option<DeviceRves>,
    /// Whether the host's copies changed since the last upload.
    dirty: bool,
    counters: BatchCounters,
}

impl GpuBatch {
    /// Brings the device's state back into the host's copies.
    fn sync_to_host(&mut self) -> Result<()> {
        let Some(d) = self.device.as_mut().filter(|d| d.ahead) else { return Ok(()) };
        for set in &d.sets {
            let sph = self.gpu.read(&set.sph)?;
            let pf = self.gpu.read(&set.pf)?;
            let ints = self.gpu.read(&set.ints)?;
            self.counters.submissions += 3;
            set.layout.download(
                &mut self.shadows[set.range.clone()],
                &set.records,
                bytemuck::cast_slice(&sph),
                bytemuck::cast_slice(&pf),
                bytemuck::cast_slice(&ints),
            )?;
        }
        d.ahead = false;
        Ok(())
    }

    /// One call of `orders` on the device: each RVE's report, the pair places it needs if it
    /// stopped for want of them, and whether a check found its time step above its contacts'
    /// bound. One submission does every set's dispatches and copies their records back; a
    /// software adapter may need more (see `Gpu::rebuilds`).
    fn submit(&mut self, orders: &[RveOrder]) -> Result<Vec<(RveReport, Option<usize>, bool)>> {
        if self.dirty || self.device.is_none() {
            self.sync_to_host()?;
            self.upload()?;
        }
        let gpu = self.gpu.clone();
        let d = self.device.as_mut().ok_or_else(|| GraniteError::Other("no RVE on the device".into()))?;
        let steps = |o: &RveOrder| o.full_steps + u64::from(o.last_step > 0.0);
        let rebuilds_before: Vec<f64> = d
            .sets
            .iter()
            .flat_map(|s| s.records.chunks(layout::RVE_STRIDE))
            .map(|r| r[Rec::Rebuilds as usize])
            .collect();
        for set in &mut d.sets {
            let orders = &orders[set.range.clone()];
            for (r, order) in orders.iter().enumerate() {
                let rec = set.record(r);
                for a in 0..3 {
                    for b in 0..3 {
                        rec[Rec::L as usize + 3 * a + b] = order.velocity_gradient[(a, b)];
                    }
                }
                rec[Rec::Steps as usize] = order.full_steps as f64;
                rec[Rec::LastDt as usize] = order.last_step;
                rec[Rec::Error as usize] = 0.0;
                rec[Rec::Taken as usize] = 0.0;
                rec[Rec::DtLimit as usize] = 0.0;
                rec[Rec::DtSay as usize] = 0.0;
                rec[Rec::Tests as usize] = 0.0;
            }
            // Workgroups start in index order: the longest orders first.
            let mut queue: Vec<usize> = (0..orders.len()).collect();
            queue.sort_by_key(|&r| std::cmp::Reverse(steps(&orders[r])));
            for (w, &r) in queue.iter().enumerate() {
                set.record(w)[Rec::Queue as usize] = r as f64;
            }
            gpu.queue.write_buffer(&set.rve, 0, bytemuck::cast_slice(&set.records));
        }
        // Submissions of as many dispatches as the longest order needs, until every RVE has taken
        // its steps (a dispatch may end early: see `Gpu::rebuilds`).
        let mut taken: Vec<f64> = vec![0.0; orders.len()];
        loop {
            let left = d
                .sets
                .iter()
                .flat_map(|set| {
                    set.range.clone().enumerate().map(move |(r, global)| {
                        steps(&orders[global])
                            .saturating_sub(set.records[r * layout::RVE_STRIDE + Rec::Taken as usize] as u64)
                    })
                })
                .max()
                .unwrap_or(0);
            let dispatches = left.div_ceil(u64::from(gpu.chunk)).max(1);
            let mut encoder = gpu.device.create_command_encoder(&Default::default());
            {
                let timestamp_writes = d.timestamps.as_ref().map(|(q, _)| wgpu::ComputePassTimestampWrites {
                    query_set: q,
                    beginning_of_pass_write_index: Some(0),
                    end_of_pass_write_index: Some(1),
                });
                let mut pass =
                    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
                pass.set_pipeline(&d.pipeline);
                for _ in 0..dispatches {
                    for set in &d.sets {
                        pass.set_bind_group(0, &set.bind_group, &[]);
                        pass.dispatch_workgroups(set.range.len() as u32, 1, 1);
                    }
                }
            }
            let mut at = 0;
            for set in &d.sets {
                encoder.copy_buffer_to_buffer(&set.rve, 0, &d.staging, at, set.rve.size());
                at += set.rve.size();
            }
            if let Some((q, resolved)) = &d.timestamps {
                encoder.resolve_query_set(q, 0..2, resolved, 0);
                encoder.copy_buffer_to_buffer(resolved, 0, &d.staging, at, 16);
            }
            gpu.queue.submit([encoder.finish()]);
            self.counters.submissions += 1;
            d.ahead = true;
            let bytes = gpu.map_and_read(&d.staging)?;
            let mut at = 0;
            for set in &mut d.sets {
                let len = set.records.len();
                set.records.copy_from_slice(bytemuck::cast_slice(&bytes[at..at + 8 * len]));
                at += 8 * len;
            }
            if d.timestamps.is_some() {
                let ticks: &[u64] = bytemuck::cast_slice(&bytes[at..at + 16]);
                let seconds =
                    ticks[1].saturating_sub(ticks[0]) as f64 * f64::from(gpu.queue.get_timestamp_period()) * 1e-9;
                *self.counters.device_seconds.get_or_insert(0.0) += seconds;
            }
            let mut unfinished = Vec::new();
            let mut now = vec![0.0; orders.len()];
            for set in &d.sets {
                for (r, global) in set.range.clone().enumerate() {
                    now[global] = set.records[r * layout::RVE_STRIDE + Rec::Taken as usize];
                    if !set.layout.finished(&set.records, r) {
                        unfinished.push(global);
                    }
                }
            }
            if unfinished.is_empty() {
                break;
            }
            if unfinished.iter().all(|&r| now[r] <= taken[r]) {
                return Err(GraniteError::Other(format!(
                    "device \"gpu\" ({}): the kernel stopped RVE {} before its last step (a driver's limit on a \
                     kernel's loops or time?)",
                    gpu.name, unfinished[0]
                )));
            }
            taken = now;
        }
        let mut reports = Vec::with_capacity(orders.len());
        for set in &d.sets {
            for (r, global) in set.range.clone().enumerate() {
                let rec = &set.records[r * layout::RVE_STRIDE..(r + 1) * layout::RVE_STRIDE];
                self.counters.pair_tests += rec[Rec::Tests as usize] as u64;
                let rebuilds = rec[Rec::Rebuilds as usize] - rebuilds_before[global];
                self.counters.sphere_searches += (rebuilds * rec[Rec::Count as usize]) as u64;
                let mut report = set.layout.report(&set.records, r);
                let above = set.layout.time_step_above(&set.records, r);
                let dt_above = above.is_some();
                if let Some(above) = above.filter(|a| a.say) {
                    let world = &self.shadows[global].world;
                    let sphere = world.spheres.id.get(above.sphere).copied().unwrap_or(above.sphere as u64);
                    report.events.push(granite_core::dem::stability::time_step_warning(
                        above.step,
                        above.time,
                        above.dt,
                        above.limit,
                        sphere,
                        above.contacts,
                    ));
                }
                reports.push((report, set.layout.pairs_wanted(&set.records, r), dt_above));
            }
        }
        Ok(reports)
    }

    /// Makes the device's state the host's copies'.
    fn upload(&mut self) -> Result<()> {
        let law = self.law.as_ref().ok_or_else(|| GraniteError::Other("no RVE on the device".into()))?;
        let dispatching = layout::Dispatching {
            chunk: self.gpu.chunk,
            rebuilds: self.gpu.rebuilds,
            force_rebuild: self.force_rebuild,
        };
        let spheres = self.shadows.iter().map(|s| s.world.spheres.len()).max().unwrap_or(0);
        let pipeline =
            self.gpu.pipeline(self.workgroup.unwrap_or_else(|| self.gpu.workgroup_size(spheres)), law.law.wgsl)?;
        let device = &self.gpu.device;
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let make = |label: &str, bytes: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: storage,
            })
        };
        let mut sets = Vec::new();
        let rooms = layout::rooms(&self.shadows, &self.least_pairs);
        for range in layout::split(&self.shadows, &rooms, law, self.max_binding)? {
            let rves = &self.shadows[range.clone()];
            let layout = Layout::new(rves, &rooms[range.clone()], law)?;
            let data = layout.upload(rves, law, dispatching)?;
            let consts = make("consts", bytemuck::cast_slice(&data.consts));
            let rve = make("rve", bytemuck::cast_slice(&data.rve));
            let sph = make("sph", bytemuck::cast_slice(&data.sph));
            let pf = make("pf", bytemuck::cast_slice(&data.pf));
            let ints = make("ints", bytemuck::cast_slice(&data.ints));
            let tally = make("tally", bytemuck::cast_slice(&data.tally));
            let buffers = [&consts, &rve, &sph, &pf, &ints, &tally];
            let bytes = buffers.iter().map(|b| b.size()).sum();
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("rves"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &buffers
                    .iter()
                    .enumerate()
                    .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
                    .collect::<Vec<_>>(),
            });
            sets.push(BufferSet { range, layout, rve, sph, pf, ints, bind_group, records: data.rve, bytes });
        }
        let records: u64 = sets.iter().map(|s| s.rve.size()).sum();
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("records back"),
            size: records + 16,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let timestamps = self.gpu.timestamps.then(|| {
            let query = device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("call time"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            });
            let resolved = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("call time resolved"),
                size: 16,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            (query, resolved)
        });
        self.counters.device_bytes = sets.iter().map(|s| s.bytes).sum::<u64>() + staging.size();
        self.counters.chunks = sets.len() as u64;
        self.device = Some(DeviceRves { pipeline, sets, staging, timestamps, ahead: false });
        self.dirty = false;
        Ok(())
    }
}

impl GpuBatch {
    /// The CPU engine's proof for the RVEs whose time step a check on the device found above
    /// their contacts' bound (and that stop on it): Lanczos iteration on their contacts as the
    /// call left them; a time step they provably cannot follow stops the RVE with the CPU's
    /// words. The device only screens (Gershgorin's bound, at the CPU engine's steps).
    fn prove_time_steps(&mut self, reports: &mut [(RveReport, Option<usize>, bool)]) -> Result<()> {
        let suspects: Vec<usize> = (0..reports.len())
            .filter(|&r| reports[r].2 && reports[r].0.failure.is_none() && self.shadows[r].stop_on_unstable_dt)
            .collect();
        if suspects.is_empty() {
            return Ok(());
        }
        self.sync_to_host()?;
        for r in suspects {
            let mut probe = self.shadows[r].world.clone();
            probe.set_time_step_check_state(None, true);
            if let Err(e) = probe.check_time_step(true) {
                reports[r].0.failure = Some(e.to_string());
            }
        }
        Ok(())
    }
}

impl RveBatch for GpuBatch {
    fn device_name(&self) -> String {
        self.gpu.name.clone()
    }
    fn len(&self) -> usize {
        self.shadows.len()
    }
    fn push(&mut self, rves: Vec<Rve>) -> Result<()> {
        let rves: Vec<DemSim> = rves.into_iter().map(Rve::into_dem).collect();
        for sim in &rves {
            let law = layout::LawConstants::of(sim)?;
            match &self.law {
                None => self.law = Some(law),
                Some(l) if *l != law => {
                    return Err(GraniteError::Setup(
                        "device \"gpu\": the RVEs of one material must share one contact law and its parameters".into(),
                    ))
                }
                Some(_) => {}
            }
        }
        self.sync_to_host()?;
        self.least_pairs.extend(std::iter::repeat_n(0, rves.len()));
        self.shadows.extend(rves);
        self.dirty = true;
        Ok(())
    }
    fn retain(&mut self, keep: &[bool]) -> Result<()> {
        self.sync_to_host()?;
        let mut k = keep.iter();
        self.shadows.retain(|_| *k.next().unwrap_or(&true));
        let mut k = keep.iter();
        self.least_pairs.retain(|_| *k.next().unwrap_or(&true));
        self.dirty = true;
        Ok(())
    }
    fn step(&mut self, orders: &[RveOrder]) -> Result<Vec<RveReport>> {
        if orders.len() != self.shadows.len() {
            return Err(GraniteError::Other(format!("{} orders for {} RVEs", orders.len(), self.shadows.len())));
        }
        if self.shadows.is_empty() {
            return Ok(Vec::new());
        }
        self.counters.calls += 1;
        let mut reports = self.submit(orders)?;
        // RVEs whose lists outgrew their room (a cell flattened to a few reaches: more images in
        // reach) go on from where they stopped with room for twice the pairs they needed.
        for _ in 0..MOST_ROOM_GROWTHS {
            let short: Vec<usize> = (0..orders.len()).filter(|&r| reports[r].1.is_some()).collect();
            if short.is_empty() {
                break;
            }
            for &r in &short {
                self.least_pairs[r] = 2 * reports[r].1.unwrap_or(0);
            }
            self.sync_to_host()?;
            self.dirty = true;
            let rest: Vec<RveOrder> = (0..orders.len())
                .map(|r| {
                    let o = &orders[r];
                    let taken = reports[r].0.steps;
                    if reports[r].1.is_none() {
                        RveOrder { full_steps: 0, last_step: 0.0, ..*o }
                    } else if taken < o.full_steps {
                        RveOrder { full_steps: o.full_steps - taken, ..*o }
                    } else {
                        RveOrder { full_steps: 0, ..*o }
                    }
                })
                .collect();
            let again = self.submit(&rest)?;
            for r in short {
                let (taken, said, above) = (reports[r].0.steps, std::mem::take(&mut reports[r].0.events), reports[r].2);
                reports[r] = again[r].clone();
                reports[r].0.steps += taken;
                reports[r].0.events.splice(0..0, said);
                reports[r].2 |= above;
            }
        }
        self.prove_time_steps(&mut reports)?;
        Ok(reports.into_iter().map(|(report, _, _)| report).collect())
    }
    fn get(&mut self, index: usize) -> Result<Rve> {
        self.sync_to_host()?;
        self.shadows
            .get(index)
            .cloned()
            .map(Rve::as_is)
            .ok_or_else(|| GraniteError::Other(format!("no RVE {index} on the device")))
    }
    fn set(&mut self, index: usize, rve: Rve) -> Result<()> {
        let rve = rve.into_dem();
        layout::LawConstants::of(&rve)?;
        self.sync_to_host()?;
        let slot =
            self.shadows.get_mut(index).ok_or_else(|| GraniteError::Other(format!("no RVE {index} on the device")))?;
        *slot = rve;
        self.least_pairs[index] = 0;
        self.dirty = true;
        Ok(())
    }
    fn counters(&self) -> BatchCounters {
        self.counters
    }
}

impl Failure {
    /// The failure in the CPU engine's words.
    pub fn describe(self, value: f64, room: f64) -> String {
        match self {
            Failure::TooFast => format!(
                "a sphere moved {value:.4e} m since the candidate lists were built, more than half the skin plus the \
                 smallest radius, so contacts would be missed: the forces are too large for this time step; lower dt"
            ),
            Failure::NotFinite => "non-finite position or velocity; the time step may be too large".into(),
            Failure::TooManyPairs => format!(
                "the RVE's candidate pairs ({value}) outgrew the device's room for {room} (lower the skin)"
            ),
            Failure::CellCollapsed => format!(
                "periodic cell collapsed: a width {value:.4e} m (between opposite faces) below 1/64 of the interaction reach"
            ),
        }
    }
}
