//! `sandstep node`: the simulation as a ROS 2 node on ros2-client (RustDDS). One thread steps
//! the simulation a control tick at a time; between ticks it takes commands and service
//! requests, then publishes and records what is due. Sim time throughout (`/clock`).

use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions as RosNodeOptions, Server,
    ServiceMapping, ServiceTypeName, Subscription,
};
use serde::Serialize;

use super::commands::{Command, CommandState};
use super::publishing::{resolve, PublishError, Publishing};
use super::qos;
use crate::bag::{BagInfo, BagWriter};
use crate::msgs::{
    Float64, Float64MultiArray, RosMessage, ServiceResponse, SetBoolRequest, TriggerRequest, Twist,
};
use crate::progress::Progress;
use crate::robot::GaitCommand;
use crate::scene::config::ServiceMappingConfig;
use crate::scene::RunError;
use crate::scene::{Scene, Simulation};

/// Command topics, relative to the node's namespace.
pub const GAIT_FREQUENCY_TOPIC: &str = "gait/frequency";
pub const CMD_VEL_TOPIC: &str = "cmd_vel";
pub const LEG_VELOCITY_TOPIC: &str = "leg_velocity_controller/commands";
/// Services, private to the node (`~/reset`, `~/pause`).
pub const RESET_SERVICE: &str = "reset";
pub const PAUSE_SERVICE: &str = "pause";

/// Largest ROS_DOMAIN_ID that maps to valid UDP ports (the ROS 2 documentation's limit).
const MAX_DOMAIN_ID: u16 = 232;
/// Wall time between polls while paused.
const PAUSED_POLL: Duration = Duration::from_millis(5);
/// Wall time between progress updates.
const PROGRESS_INTERVAL: Duration = Duration::from_millis(250);

/// How to run the node.
#[derive(Clone, Debug, Default)]
pub struct NodeRunOptions {
    /// Stop after this much simulated time (s); run until stopped otherwise.
    pub duration_s: Option<f64>,
    /// Pace the simulation to the wall clock (never faster than real time).
    pub realtime: bool,
    /// Record into this bag directory; `None` = no bag.
    pub bag_dir: Option<PathBuf>,
    /// Where the node reports its simulated time, real-time factor and commands.
    pub progress: Progress,
    /// Set by Ctrl-C / SIGTERM: stop inside the current substep.
    pub stop: Arc<AtomicBool>,
}

/// What a node run did (`sandstep node --json` prints it).
#[derive(Clone, Debug, Serialize)]
pub struct NodeSummary {
    pub node: String,
    pub domain_id: u16,
    /// Simulated time published at the end (s; resets do not turn it back).
    pub sim_time_s: f64,
    pub wall_time_s: f64,
    /// Simulated over wall time while running (paused time excluded).
    pub real_time_factor: f64,
    pub commands_received: u64,
    pub commands_rejected: u64,
    pub resets: u64,
    /// The bag, when recording.
    pub bag: Option<BagInfo>,
}

/// Why the node stopped with an error.
#[derive(thiserror::Error, Debug)]
pub enum NodeError {
    #[error("ROS_DOMAIN_ID={0}: must be a whole number from 0 to {MAX_DOMAIN_ID}")]
    DomainId(String),
    #[error("ROS 2: {0}")]
    Ros(String),
    #[error(transparent)]
    Publish(#[from] PublishError),
    #[error(transparent)]
    Run(#[from] RunError),
    #[error("{error}\n(the bag up to this point is in {})", bag.display())]
    WithBag { error: Box<NodeError>, bag: PathBuf },
}

/// The DDS domain from `ROS_DOMAIN_ID` (default 0).
pub fn domain_id_from_env() -> Result<u16, NodeError> {
    match std::env::var("ROS_DOMAIN_ID") {
        Err(_) => Ok(0),
        Ok(s) if s.trim().is_empty() => Ok(0),
        Ok(s) => s
            .trim()
            .parse::<u16>()
            .ok()
            .filter(|d| *d <= MAX_DOMAIN_ID)
            .ok_or(NodeError::DomainId(s)),
    }
}

fn ros_err(what: &str) -> impl Fn(&dyn std::fmt::Debug) -> NodeError + '_ {
    move |e| NodeError::Ros(format!("{what}: {e:?}"))
}

/// A DDS participant in `domain_id`, only on loopback if asked, and a node on it.
fn create_node(scene: &Scene, domain_id: u16) -> Result<Node, NodeError> {
    let cfg = &scene.config.node;
    let mut builder = rustdds::DomainParticipantBuilder::new(domain_id);
    if cfg.loopback_only {
        builder = builder.with_only_networks([Ipv4Addr::LOCALHOST]);
    }
    let participant = builder
        .build()
        .map_err(|e| ros_err("DDS participant")(&e))?;
    let context =
        Context::from_domain_participant(participant).map_err(|e| ros_err("ROS 2 context")(&e))?;
    let name = NodeName::new(&cfg.namespace, &cfg.name)
        .map_err(|e| ros_err("node name (node.name, node.namespace)")(&e))?;
    context
        .new_node(name, RosNodeOptions::new().enable_rosout(true))
        .map_err(|e| ros_err("node")(&e))
}

fn subscribe<M: RosMessage + ros2_client::Message>(
    node: &mut Node,
    name: &str,
) -> Result<Subscription<M>, NodeError> {
    let err = ros_err(name);
    let qos = qos::command();
    let ty = M::TYPE;
    let topic = node
        .create_topic(
            &Name::parse(name).map_err(|e| err(&e))?,
            MessageTypeName::new(ty.package, ty.name),
            &qos,
        )
        .map_err(|e| err(&e))?;
    node.create_subscription(&topic, Some(qos))
        .map_err(|e| err(&e))
}

fn serve<Req>(
    node: &mut Node,
    name: &str,
    ty: &str,
    mapping: ServiceMapping,
) -> Result<Server<Req, ServiceResponse>, NodeError>
where
    Req: ros2_client::Message + Clone + 'static,
{
    let err = ros_err(name);
    node.create_server(
        mapping,
        &Name::parse(name).map_err(|e| err(&e))?,
        &ServiceTypeName::new("std_srvs", ty),
        qos::service(),
        qos::service(),
    )
    .map_err(|e| err(&e))
}

/// The command subscriptions and services of the node.
struct Inputs {
    gait_frequency: (String, Subscription<Float64>),
    cmd_vel: (String, Subscription<Twist>),
    leg_velocities: (String, Subscription<Float64MultiArray>),
    reset: Server<TriggerRequest, ServiceResponse>,
    pause: Server<SetBoolRequest, ServiceResponse>,
}

impl Inputs {
    fn new(node: &mut Node, scene: &Scene) -> Result<Self, NodeError> {
        let cfg = &scene.config.node;
        let ns = cfg.namespace.as_str();
        let private = resolve(ns, &cfg.name);
        let mapping = match cfg.service_mapping {
            ServiceMappingConfig::Enhanced => ServiceMapping::Enhanced,
            ServiceMappingConfig::Cyclone => ServiceMapping::Cyclone,
            ServiceMappingConfig::Basic => ServiceMapping::Basic,
        };
        let topic = |name| resolve(ns, name);
        let (f, v, l) = (
            topic(GAIT_FREQUENCY_TOPIC),
            topic(CMD_VEL_TOPIC),
            topic(LEG_VELOCITY_TOPIC),
        );
        Ok(Inputs {
            gait_frequency: (f.clone(), subscribe(node, &f)?),
            cmd_vel: (v.clone(), subscribe(node, &v)?),
            leg_velocities: (l.clone(), subscribe(node, &l)?),
            reset: serve(node, &resolve(&private, RESET_SERVICE), "Trigger", mapping)?,
            pause: serve(node, &resolve(&private, PAUSE_SERVICE), "SetBool", mapping)?,
        })
    }

    /// Every command that arrived since the last call, with its topic, in arrival order per
    /// topic.
    fn take_commands(&self) -> Vec<(String, Command)> {
        let mut out = Vec::new();
        fn drain<M: RosMessage + ros2_client::Message>(
            (name, sub): &(String, Subscription<M>),
            wrap: fn(M) -> Command,
            out: &mut Vec<(String, Command)>,
        ) {
            loop {
                match sub.take() {
                    Ok(Some((msg, _))) => out.push((name.clone(), wrap(msg))),
                    Ok(None) => break,
                    Err(e) => {
                        eprintln!("warning: reading {name}: {e:?}");
                        break;
                    }
                }
            }
        }
        drain(&self.gait_frequency, Command::GaitFrequency, &mut out);
        drain(&self.cmd_vel, Command::CmdVel, &mut out);
        drain(&self.leg_velocities, Command::LegVelocities, &mut out);
        out
    }
}

/// The running node's state between ticks.
struct Session<'a> {
    scene: &'a Scene,
    sim: Simulation,
    publishing: Publishing,
    commands: CommandState,
    paused: bool,
    summary: NodeSummary,
}

impl Session<'_> {
    /// Applies and records the commands that arrived.
    fn handle_commands(&mut self, inputs: &Inputs) -> Result<(), NodeError> {
        for (topic, cmd) in inputs.take_commands() {
            let stamp = self.publishing.stamp(&self.sim);
            match &cmd {
                Command::GaitFrequency(m) => self.publishing.record(&topic, stamp, m)?,
                Command::CmdVel(m) => self.publishing.record(&topic, stamp, m)?,
                Command::LegVelocities(m) => self.publishing.record(&topic, stamp, m)?,
            }
            match self.commands.receive(&cmd, stamp.as_secs()) {
                Ok(gait) => {
                    self.sim.command(gait);
                    self.summary.commands_received += 1;
                }
                Err(e) => {
                    eprintln!("warning: ignored a command: {e}");
                    self.summary.commands_rejected += 1;
                }
            }
        }
        if let Some(gait) = self
            .commands
            .tick(self.publishing.stamp(&self.sim).as_secs())
        {
            self.sim.command(gait);
        }
        Ok(())
    }

    /// Answers `~/reset` and `~/pause`.
    fn handle_services(&mut self, inputs: &Inputs) -> Result<(), NodeError> {
        while let Some((id, _)) = inputs.reset.receive_request().unwrap_or(None) {
            let response = match self.reset() {
                Ok(()) => ServiceResponse {
                    success: true,
                    message: format!(
                        "reset to the scene's initial state at t = {:.9} s",
                        self.publishing.time_offset_s
                    ),
                },
                Err(e) => return Err(e),
            };
            if let Err(e) = inputs.reset.send_response(id, response) {
                eprintln!("warning: answering reset: {e:?}");
            }
        }
        while let Some((id, request)) = inputs.pause.receive_request().unwrap_or(None) {
            let was = self.paused;
            self.paused = request.data;
            let response = ServiceResponse {
                success: true,
                message: format!(
                    "{} (was {})",
                    if self.paused { "paused" } else { "running" },
                    if was { "paused" } else { "running" }
                ),
            };
            if let Err(e) = inputs.pause.send_response(id, response) {
                eprintln!("warning: answering pause: {e:?}");
            }
        }
        Ok(())
    }

    /// Rebuilds the scene; the published clock keeps running forward.
    fn reset(&mut self) -> Result<(), NodeError> {
        let fresh = Simulation::new_unless(self.scene, &self.sim.stop_request())?;
        self.publishing.time_offset_s += self.sim.time_s();
        self.sim = fresh;
        self.commands.reset();
        self.publishing.restart(&self.sim);
        self.summary.resets += 1;
        Ok(())
    }

    /// Published time (s).
    fn now_s(&self) -> f64 {
        self.publishing.time_offset_s + self.sim.time_s()
    }
}

/// Runs `scene` as a ROS 2 node until `opts.duration_s` of simulated time or a stop request.
/// The bag is finished in every case, errors included.
pub fn run_node(scene: &Scene, opts: &NodeRunOptions) -> Result<NodeSummary, NodeError> {
    let domain_id = domain_id_from_env()?;
    let mut node = create_node(scene, domain_id)?;
    let spinner = node.spinner().map_err(|e| ros_err("spinner")(&e))?;
    std::thread::Builder::new()
        .name("ros-spinner".into())
        .spawn(move || {
            if let Err(e) = smol::block_on(spinner.spin()) {
                eprintln!("warning: ROS 2 spinner stopped: {e:?}");
            }
        })
        .map_err(|e| ros_err("spinner thread")(&e))?;

    let sim = Simulation::new_unless(scene, &opts.stop)?;
    let bag = match &opts.bag_dir {
        Some(dir) => Some(BagWriter::create(dir).map_err(PublishError::from)?),
        None => None,
    };
    let publishing = Publishing::new(scene, &sim, Some(&mut node), bag)?;
    let inputs = Inputs::new(&mut node, scene)?;
    let default_gait = scene
        .config
        .robot
        .as_ref()
        .map(|r| GaitCommand::from_config(&r.gait))
        .unwrap_or_default();
    let mut session = Session {
        scene,
        sim,
        publishing,
        commands: CommandState::new(default_gait, &scene.config.node),
        paused: false,
        summary: NodeSummary {
            node: resolve(&scene.config.node.namespace, &scene.config.node.name),
            domain_id,
            sim_time_s: 0.0,
            wall_time_s: 0.0,
            real_time_factor: 0.0,
            commands_received: 0,
            commands_rejected: 0,
            resets: 0,
            bag: None,
        },
    };
    let outcome = run_loop(&mut session, &inputs, opts);
    // Finish the bag whatever happened, so that nothing recorded is lost.
    let bag_dir = session.publishing.bag_dir().map(PathBuf::from);
    let finished = session.publishing.finish();
    node.stop_spinner();
    match (outcome, finished) {
        (Ok(()), Ok(bag)) => {
            session.summary.bag = bag;
            Ok(session.summary)
        }
        (Err(error), _) => Err(match bag_dir {
            Some(bag) => NodeError::WithBag {
                error: Box::new(error),
                bag,
            },
            None => error,
        }),
        (Ok(()), Err(e)) => Err(e.into()),
    }
}

fn run_loop(
    session: &mut Session,
    inputs: &Inputs,
    opts: &NodeRunOptions,
) -> Result<(), NodeError> {
    let period_s = 1.0 / session.scene.config.node.state_rate_hz;
    let progress = &opts.progress;
    progress.start_run(&session.summary.node, opts.duration_s);
    session.publishing.publish_static(&session.sim)?;
    session.publishing.publish_due(&mut session.sim)?;
    let start = Instant::now();
    // Pacing origin: wall instant and published sim time when running (re)started.
    let mut pace_origin = (Instant::now(), session.now_s());
    let (mut running_wall_s, mut running_sim_s) = (0.0f64, 0.0f64);
    let mut last_progress = Instant::now();
    loop {
        if opts.stop.load(Ordering::Relaxed) {
            break;
        }
        if opts.duration_s.is_some_and(|d| session.now_s() >= d - 1e-9) {
            break;
        }
        session.handle_commands(inputs)?;
        let was_paused = session.paused;
        session.handle_services(inputs)?;
        if session.paused {
            std::thread::sleep(PAUSED_POLL);
            continue;
        }
        if was_paused {
            pace_origin = (Instant::now(), session.now_s());
        }
        let tick_wall = Instant::now();
        let tick_sim = session.now_s();
        let mut target = session.sim.time_s() + period_s;
        if let Some(d) = opts.duration_s {
            target = target.min(d - session.publishing.time_offset_s);
        }
        progress.abandon_on_error(session.sim.advance_to(target))?;
        session.publishing.publish_due(&mut session.sim)?;
        if opts.realtime {
            let ahead = (session.now_s() - pace_origin.1) - pace_origin.0.elapsed().as_secs_f64();
            if ahead > 0.0 {
                std::thread::sleep(Duration::from_secs_f64(ahead));
            }
        }
        running_wall_s += tick_wall.elapsed().as_secs_f64();
        running_sim_s += session.now_s() - tick_sim;
        if last_progress.elapsed() >= PROGRESS_INTERVAL {
            last_progress = Instant::now();
            let cmd = session.commands.current();
            progress.advance(session.now_s(), || {
                format!(
                    "real-time factor {:.3}, gait {:.2} Hz, {} commands",
                    running_sim_s / running_wall_s.max(1e-9),
                    cmd.frequency_hz,
                    session.summary.commands_received
                )
            });
        }
    }
    progress.done();
    let s = &mut session.summary;
    s.sim_time_s = session.publishing.time_offset_s + session.sim.time_s();
    s.wall_time_s = start.elapsed().as_secs_f64();
    s.real_time_factor = running_sim_s / running_wall_s.max(1e-9);
    Ok(())
}
