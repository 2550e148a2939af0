//! A subcommand's command line rebuilt from its typed arguments, for the processes `upc run` and
//! `upc capability` start: the flags come from clap's own definition of the type and every field
//! is listed by name (a destructuring without `..`), so a field added, renamed or removed does
//! not compile until its command line follows, and a renamed flag follows by itself.

use std::ffi::OsString;
use std::path::PathBuf;

/// A type whose values can be written back as the command line clap parses into it.
pub trait ToArgv {
    fn write(&self, w: &mut Argv);
}

/// The command line being written, and the definition of the arguments it is written for.
pub struct Argv {
    cmd: clap::Command,
    out: Vec<OsString>,
}

/// A value as one command-line word.
pub trait ArgValue {
    fn word(&self) -> OsString;
}

impl ArgValue for String {
    fn word(&self) -> OsString {
        self.into()
    }
}

impl ArgValue for PathBuf {
    fn word(&self) -> OsString {
        self.into()
    }
}

impl ArgValue for f64 {
    fn word(&self) -> OsString {
        // Display is the shortest text that parses back to the same f64.
        self.to_string().into()
    }
}

impl ArgValue for upc::forecast::ForecastShape {
    fn word(&self) -> OsString {
        self.to_string().into()
    }
}

/// A `clap::ValueEnum` value as its command-line name.
pub struct Choice<'a, T>(pub &'a T);

impl<T: clap::ValueEnum> ArgValue for Choice<'_, T> {
    fn word(&self) -> OsString {
        self.0
            .to_possible_value()
            .map(|v| v.get_name().to_owned())
            .unwrap_or_default()
            .into()
    }
}

impl Argv {
    /// `sub` and its arguments `args`, as `upc sub …` would be spelled.
    pub fn of<T: clap::Args + ToArgv>(sub: &str, args: &T) -> Vec<OsString> {
        let mut w = Argv {
            cmd: T::augment_args(clap::Command::new("upc")),
            out: vec![sub.into()],
        };
        args.write(&mut w);
        w.out
    }

    /// The flag of the field `id`, as clap defines it (`--set` for `sets`).
    fn flag(&self, id: &str) -> OsString {
        let long = self
            .cmd
            .get_arguments()
            .find(|a| a.get_id() == id)
            .and_then(|a| a.get_long());
        // Unknown to clap: its default spelling (a test round-trips every subcommand).
        let name = long.map_or_else(|| id.replace('_', "-"), str::to_owned);
        format!("--{name}").into()
    }

    pub fn val(&mut self, id: &str, v: &impl ArgValue) {
        let flag = self.flag(id);
        self.out.extend([flag, v.word()]);
    }

    pub fn opt(&mut self, id: &str, v: &Option<impl ArgValue>) {
        if let Some(v) = v {
            self.val(id, v);
        }
    }

    pub fn many(&mut self, id: &str, vs: &[impl ArgValue]) {
        for v in vs {
            self.val(id, v);
        }
    }

    pub fn switch(&mut self, id: &str, on: &bool) {
        if *on {
            let flag = self.flag(id);
            self.out.push(flag);
        }
    }

    pub fn choice<T: clap::ValueEnum>(&mut self, id: &str, v: &T) {
        self.val(id, &Choice(v));
    }

    pub fn opt_choice<T: clap::ValueEnum>(&mut self, id: &str, v: &Option<T>) {
        if let Some(v) = v {
            self.choice(id, v);
        }
    }

    /// A flattened group of arguments.
    pub fn nested(&mut self, args: &impl ToArgv) {
        args.write(self);
    }
}

/// `fields!(w; how field, …)`: `w.how("field", field)` for fields bound by name, so that the
/// field and the name clap knows it by are one identifier.
macro_rules! fields {
    ($w:expr; $($how:ident $field:ident),* $(,)?) => {
        $( $w.$how(stringify!($field), $field); )*
    };
}
pub(crate) use fields;

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use clap::Parser;
    use upc::config::ControllerKind;

    use super::Argv;
    use crate::cli::bridge::BridgeArgs;
    use crate::cli::cell::CellArgs;
    use crate::cli::common::{CaseSetup, ConfigArgs, RobotArg};
    use crate::cli::controller::ControllerArgs;
    use crate::cli::forecast::ForecastArgs;
    use crate::cli::run::{CpuLayout, RunArgs, Which};
    use crate::cli::sim::{ModeChoice, PlantArgs, PlantChoice, SimArgs};
    use crate::{Cli, Command};

    fn config() -> ConfigArgs {
        ConfigArgs {
            configs: vec!["a.toml".into(), "b c.toml".into()],
            sets: vec!["x.y=1".into(), "s=\"-v\"".into()],
        }
    }

    fn robot() -> RobotArg {
        RobotArg { robot: "g1".into() }
    }

    /// Parse `upc <argv>` back.
    fn parse(argv: Vec<std::ffi::OsString>) -> Command {
        let mut full = vec![std::ffi::OsString::from("upc")];
        full.extend(argv.clone());
        Cli::try_parse_from(full)
            .unwrap_or_else(|e| panic!("{argv:?}: {e}"))
            .command
    }

    // Every field set away from its default: what clap parses back is what was written.
    #[test]
    fn every_child_command_line_parses_back_to_its_arguments() {
        let sim = SimArgs {
            plant: PlantArgs {
                mode: Some(ModeChoice::Realtime),
                duration: Some(0.1 + 0.2),
                configs: vec!["sim.toml".into()],
                sets: vec!["sim.dt=0.002".into()],
                prefix: Some("p".into()),
                scenario: Some("single_impact".into()),
                sensing: Some(upc::sim::sensors::Sensing::Realistic),
                robot: robot(),
            },
            simulator: PlantChoice::Mujoco,
            bundle: Some("bundle".into()),
            rrd: Some("sim.rrd".into()),
            recording_id: Some("r".into()),
            connect: Some("rerun+http://h:1/proxy".into()),
            summary: Some("sim.json".into()),
            truth_csv: Some("sim.csv".into()),
            bus: Some(super::super::bus::BusChoice::Unitree),
            bus_settings: super::super::bus::BusSettingsArgs {
                bus_configs: vec!["b.toml".into()],
                bus_sets: vec!["bus.sim.rate=200.0".into()],
            },
        };
        let Command::Sim(back) = parse(Argv::of("sim", &sim)) else {
            panic!("not sim")
        };
        assert_eq!(format!("{back:?}"), format!("{sim:?}"));

        let bus = super::super::bus::BusArgs {
            plant: sim.plant.clone(),
            settings: sim.bus_settings.clone(),
            summary: Some("bus.json".into()),
        };
        let Command::Bus(back) = parse(Argv::of("bus", &bus)) else {
            panic!("not bus")
        };
        assert_eq!(format!("{back:?}"), format!("{bus:?}"));

        let controller = ControllerArgs {
            scenario: "s.toml".into(),
            controller: Some(ControllerKind::C2),
            realtime: true,
            robot: robot(),
            prefix: "p".into(),
            rrd: Some("c.rrd".into()),
            recording_id: "rid".into(),
            connect: Some("u".into()),
            csv: Some("c.csv".into()),
            summary: Some("c.json".into()),
            duration: Some(3.25),
            sensing: Some(upc::sim::sensors::Sensing::Truth),
            config: config(),
        };
        let Command::Controller(back) = parse(Argv::of("controller", &controller)) else {
            panic!("not controller")
        };
        assert_eq!(format!("{back:?}"), format!("{controller:?}"));

        let forecast = ForecastArgs {
            scenario: Some("s".into()),
            dt: 0.004,
            window: 3.0,
            period: 0.02,
            until: Some(7.5),
            prefix: "p".into(),
            error_scale: 1.5,
            error_shift: -0.1,
            error_shape: upc::forecast::ForecastShape::Decaying(0.3),
        };
        let Command::Forecast(back) = parse(Argv::of("forecast", &forecast)) else {
            panic!("not forecast")
        };
        assert_eq!(format!("{back:?}"), format!("{forecast:?}"));

        let bridge = BridgeArgs {
            config: config(),
            prefix: Some("p".into()),
            key_prefix: Some("lab/p".into()),
            listen: vec!["tls/127.0.0.1:1".into(), "tls/[::1]:2".into()],
            connect: vec!["tls/10.0.0.1:3".into()],
            insecure: true,
            summary: Some(PathBuf::from("b.json")),
        };
        let Command::Bridge(back) = parse(Argv::of("bridge", &bridge)) else {
            panic!("not bridge")
        };
        assert_eq!(format!("{back:?}"), format!("{bridge:?}"));

        let run = RunArgs {
            scenario: "s.toml".into(),
            controller: Which::C1,
            realtime: true,
            duration: Some(2.0),
            name: Some("n".into()),
            out: "out".into(),
            forecaster: Some("python3 f.py --x".into()),
            forecaster_over_zenoh: true,
            no_forecaster: false,
            viewer: false,
            connect: Some("u".into()),
            quiet: true,
            cpus: CpuLayout::Shared,
            forecast_error_scale: 0.5,
            forecast_error_shift: -0.25,
            forecast_error_shape: upc::forecast::ForecastShape::Truncated(0.5),
            config: config(),
            sim_sets: vec!["sim.push=\"none\"".into()],
            plant: PlantChoice::Mujoco,
            sensing: Some(upc::sim::sensors::Sensing::Realistic),
            robot: robot(),
            bus: Some(super::super::bus::BusChoice::Unitree),
            bus_settings: super::super::bus::BusSettingsArgs {
                bus_configs: vec!["b.toml".into()],
                bus_sets: vec!["bus.domain=7".into()],
            },
        };
        let Command::Run(back) = parse(Argv::of("run", &run)) else {
            panic!("not run")
        };
        assert_eq!(format!("{back:?}"), format!("{run:?}"));

        // A sweep's cell: what the Ray task runs (`--scratch` is the task's, not the cell's).
        let cell = CellArgs {
            variant: upc::capability::Variant::C1Raw,
            duration: 0.1 + 0.2,
            direction: upc::capability::Direction::Y,
            forecast_scale: 1.5,
            forecast_shift: -0.15,
            forecast_shape: "stretched:2".parse().expect("shape"),
            phantom: true,
            max: 160.0,
            tol: 2.0,
            monotone: Some(5.0),
            edge_time: 0.2,
            com_drop: 0.005,
            plant: PlantChoice::Mujoco,
            setup: CaseSetup {
                sensing: Some(upc::sim::sensors::Sensing::Realistic),
                sim_sets: vec!["sim.sensors.seed=2".into()],
                robot: robot(),
                config: config(),
            },
        };
        let mut argv = Argv::of("sweep-cell", &cell);
        argv.extend(["--scratch".into(), "s".into()]);
        let Command::SweepCell(back) = parse(argv) else {
            panic!("not sweep-cell")
        };
        assert_eq!(format!("{:?}", back.cell), format!("{cell:?}"));
    }
}
