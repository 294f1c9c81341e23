//! The viewer layout sent with every recording, so a run reads the same way every time without
//! a click: a large map on the left; on the right, stacked on one shared time axis, speeds,
//! chainage errors and speed errors of every pipeline with their ±3σ bands, then one tab of
//! diagnostics per pipeline; the events as text along the bottom. Raw logs (no pipelines) get
//! the map, speeds, position sensors' errors and the IMU.
//!
//! Written with Rerun's blueprint archetypes directly rather than the SDK's `Blueprint`
//! builder: the builder cannot yet set view properties (shared time axis, legends, axis
//! ranges) or per-entity time ranges (the GNSS trail on the map).

use rerun::external::re_log_types::{BlueprintActivationCommand, LogMsg};
use rerun::external::re_sdk_types::blueprint::archetypes::{
    ContainerBlueprint, PanelBlueprint, PlotLegend, ScalarAxis, TextLogColumns, TimeAxis,
    TimePanelBlueprint, ViewBlueprint, ViewContents, ViewportBlueprint, VisibleTimeRanges,
};
use rerun::external::re_sdk_types::blueprint::components::{
    ColumnShare, ContainerKind, Corner2D, IncludedContent, PanelState, PlayState, QueryExpression,
    RootContainer, RowShare, TimelineName, ViewClass,
};
use rerun::external::re_sdk_types::blueprint::datatypes::{TextLogColumn, TextLogColumnKind};
use rerun::external::re_sdk_types::datatypes::{self, TimeRange, TimeRangeBoundary};
use rerun::external::uuid::Uuid;
use rerun::{AsComponents, RecordingStream, RecordingStreamBuilder};

use crate::entities as ent;
use crate::series::TIMELINE;
use crate::Error;

/// What the recording holds, as far as the layout cares. Grows as entities first appear; the
/// blueprint is rebuilt from it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Layout {
    pub pipelines: Vec<PipelineLayout>,
    /// GNSS fix entities on the map (they get a trail).
    pub gnss_fixes: Vec<String>,
    pub truth: bool,
    /// Loop or balise errors against the truth.
    pub position_sensors: bool,
    /// GNSS satellites and HDOP.
    pub gnss_quality: bool,
    pub imu: bool,
    /// Tuning traces: per tuned pipeline, its value entities with their names.
    pub tune: Vec<(String, Vec<(String, String)>)>,
}

/// One pipeline's diagnostic views.
#[derive(Debug, Clone, PartialEq)]
pub struct PipelineLayout {
    pub name: String,
    pub sharing: bool,
    pub effective_sample_size: bool,
    /// Safety checks: the safe-interval plot.
    pub safety: bool,
    /// Values drawn with a band (sensor states, plane velocity errors, the learnt IMU
    /// error model): entity and title, the title saying what the band is.
    pub bands: Vec<(String, String)>,
    /// Plain line plots (an eddy-current pipeline's correlation, accelerations, counts):
    /// entity and title.
    pub lines: Vec<(String, String)>,
}

impl PipelineLayout {
    pub fn new(name: &str) -> Self {
        PipelineLayout {
            name: name.to_owned(),
            sharing: false,
            effective_sample_size: false,
            safety: false,
            bands: Vec::new(),
            lines: Vec::new(),
        }
    }
}

/// NIS axis: χ²₁'s 99.9 % point is 10.8; rejected measurements are drawn at the top.
pub const NIS_AXIS_MAX: f64 = 12.0;

/// A view or container, as the blueprint store wants it.
enum Node {
    View {
        id: Uuid,
        class: &'static str,
        name: String,
        origin: String,
        properties: Vec<(&'static str, Box<dyn AsComponents>)>,
        /// Per-entity time ranges (entity, range).
        trails: Vec<String>,
    },
    Container {
        id: Uuid,
        kind: ContainerKind,
        name: Option<String>,
        children: Vec<Node>,
        shares: Vec<f32>,
        grid_columns: Option<u32>,
    },
}

/// Stable ids: the same layout gets the same ids run after run.
fn id_of(key: &str) -> Uuid {
    // FNV-1a, 128-bit: no dependency for a name hash.
    let mut h: u128 = 0x6c62272e07bb014262b821756295c58d;
    for b in key.bytes() {
        h ^= b as u128;
        h = h.wrapping_mul(0x0000000001000000000000000000013B);
    }
    Uuid::from_u128(h)
}

fn view(class: &'static str, name: &str, origin: &str) -> Node {
    Node::View {
        id: id_of(&format!("{class}:{name}:{origin}")),
        class,
        name: name.to_owned(),
        origin: origin.to_owned(),
        properties: Vec::new(),
        trails: Vec::new(),
    }
}

/// How a plot looks beyond its data.
#[derive(Clone, Copy)]
struct PlotStyle {
    /// The whole run (first and last log time, ns), when known.
    span: Option<(i64, i64)>,
    y_range: Option<(f64, f64)>,
    legend: bool,
}

/// A time series on the shared time axis, showing the whole run.
fn plot(name: &str, origin: &str, style: PlotStyle) -> Node {
    let mut node = view("TimeSeries", name, origin);
    if let Node::View { properties, .. } = &mut node {
        // Not linked to the other plots: Rerun 0.36 opens linked time axes on a one-minute
        // window around the cursor, which hides the run (seen in the viewer; rerun-io/rerun
        // #11209 and #11621 report linked axes misbehaving). Each plot opens on the whole run
        // instead; they zoom one by one.
        let mut axis = TimeAxis::new();
        if let Some((first, last)) = style.span {
            axis = axis.with_view_range(TimeRange {
                start: TimeRangeBoundary::Absolute(datatypes::TimeInt(first)),
                end: TimeRangeBoundary::Absolute(datatypes::TimeInt(last)),
            });
        }
        properties.push(("TimeAxis", Box::new(axis)));
        properties.push((
            "PlotLegend",
            Box::new(
                PlotLegend::new()
                    .with_corner(Corner2D::LeftTop)
                    .with_visible(style.legend),
            ),
        ));
        if let Some((lo, hi)) = style.y_range {
            properties.push((
                "ScalarAxis",
                Box::new(ScalarAxis::new().with_range(datatypes::Range1D([lo, hi]))),
            ));
        }
    }
    node
}

fn container(kind: ContainerKind, name: Option<&str>, children: Vec<Node>, shares: &[f32]) -> Node {
    let key = format!(
        "{kind:?}:{}:{}",
        name.unwrap_or_default(),
        children.iter().map(Node::key).collect::<Vec<_>>().join(",")
    );
    Node::Container {
        id: id_of(&key),
        kind,
        name: name.map(str::to_owned),
        children,
        shares: shares.to_vec(),
        grid_columns: None,
    }
}

impl Node {
    fn id(&self) -> Uuid {
        match self {
            Node::View { id, .. } | Node::Container { id, .. } => *id,
        }
    }

    fn key(&self) -> String {
        self.id().to_string()
    }

    fn path(&self) -> String {
        match self {
            Node::View { id, .. } => format!("view/{id}"),
            Node::Container { id, .. } => format!("container/{id}"),
        }
    }

    fn log(&self, bp: &RecordingStream) -> rerun::RecordingStreamResult<()> {
        match self {
            Node::View {
                id,
                class,
                name,
                origin,
                properties,
                trails,
            } => {
                let path = self.path();
                bp.log(
                    format!("{path}/ViewContents"),
                    &ViewContents::new([QueryExpression::from("$origin/**")]),
                )?;
                bp.log(
                    path.as_str(),
                    &ViewBlueprint::new(ViewClass::from(*class))
                        .with_display_name(name.as_str())
                        .with_space_origin(origin.as_str()),
                )?;
                for (property, archetype) in properties {
                    bp.log(format!("{path}/{property}"), archetype.as_ref())?;
                }
                for entity in trails {
                    // Everything up to the time cursor: the trail so far.
                    let trail = datatypes::VisibleTimeRange {
                        timeline: TIMELINE.into(),
                        range: TimeRange {
                            start: TimeRangeBoundary::Infinite,
                            end: TimeRangeBoundary::AT_CURSOR,
                        },
                    };
                    bp.log(
                        ViewContents::blueprint_base_visualizer_path_for_entity(
                            *id,
                            &entity.as_str().into(),
                        ),
                        &VisibleTimeRanges::new([trail]),
                    )?;
                }
            }
            Node::Container {
                kind,
                name,
                children,
                shares,
                grid_columns,
                ..
            } => {
                for child in children {
                    child.log(bp)?;
                }
                let mut arch = ContainerBlueprint::new(*kind).with_contents(
                    children
                        .iter()
                        .map(|c| IncludedContent::from(c.path().as_str())),
                );
                if let Some(name) = name {
                    arch = arch.with_display_name(name.as_str());
                }
                if let Some(n) = grid_columns {
                    arch = arch.with_grid_columns(*n);
                }
                if !shares.is_empty() {
                    arch = match kind {
                        ContainerKind::Horizontal => {
                            arch.with_col_shares(shares.iter().map(|&s| ColumnShare::from(s)))
                        }
                        _ => arch.with_row_shares(shares.iter().map(|&s| RowShare::from(s))),
                    };
                }
                bp.log(self.path(), &arch)?;
            }
        }
        Ok(())
    }
}

impl Layout {
    /// The layout as a tree of containers and views; `span` is the run's first and last log
    /// time when known (the plots then open on the whole run).
    fn tree(&self, span: Option<(i64, i64)>) -> Node {
        let main = PlotStyle {
            span,
            y_range: None,
            legend: true,
        };
        if !self.tune.is_empty() && self.pipelines.is_empty() && !self.truth {
            return self.tune_tree(main);
        }
        let mut map = view("2D", "Map (east →, north ↑)", "/map");
        if let Node::View { trails, .. } = &mut map {
            trails.extend(self.gnss_fixes.iter().map(|e| format!("/{e}")));
            if self.truth {
                trails.push(format!("/{}", ent::TRUTH_PATH));
            }
        }
        let (right, shares) = self.plots(main, span);
        let top = container(
            ContainerKind::Horizontal,
            None,
            vec![
                map,
                container(ContainerKind::Vertical, None, right, &shares),
            ],
            &[2.0, 3.0],
        );
        let events = events_view();
        container(
            ContainerKind::Vertical,
            None,
            vec![top, events],
            &[4.0, 1.0],
        )
    }

    /// The right-hand column beside the map: speed; a raw log's sensor plots, or a fused
    /// log's errors against the truth and each pipeline's diagnostics tab; with their shares.
    fn plots(&self, main: PlotStyle, span: Option<(i64, i64)>) -> (Vec<Node>, Vec<f32>) {
        let mut right = vec![plot("Speed (m/s)", "/speed", main)];
        let mut shares = vec![1.0];
        if self.pipelines.is_empty() {
            if self.position_sensors {
                right.push(plot(
                    "Position sensors: chainage − truth (m)",
                    "/sensors/chainage_error",
                    main,
                ));
                shares.push(1.0);
            }
            if self.imu {
                right.push(plot(
                    "IMU specific force (m/s²)",
                    "/sensors/imu/specific_force",
                    main,
                ));
                right.push(plot(
                    "IMU angular rate (rad/s)",
                    "/sensors/imu/angular_rate",
                    main,
                ));
                shares.extend([1.0, 1.0]);
            }
        } else {
            if self.truth {
                right.push(plot(
                    "Chainage error: fused − truth, ±3σ (m)",
                    "/chainage_error",
                    main,
                ));
                right.push(plot(
                    "Speed error: fused − truth, ±3σ (m/s)",
                    "/speed_error",
                    main,
                ));
                shares.extend([1.2, 1.0]);
            }
            let tabs: Vec<Node> = self.pipelines.iter().map(|p| p.tab(span)).collect();
            right.push(container(
                ContainerKind::Tabs,
                Some("Diagnostics"),
                tabs,
                &[],
            ));
            shares.push(1.4);
        }
        (right, shares)
    }

    /// A tuning trace: per pipeline, the objective and the best so far over the search, and
    /// each tuned value on its own (their scales differ by decades).
    fn tune_tree(&self, main: PlotStyle) -> Node {
        let tabs = self
            .tune
            .iter()
            .map(|(pipeline, values)| {
                let objective = plot(
                    &format!("{pipeline}: objective of each evaluation, and the best so far"),
                    &format!("/{}", ent::tune_objective(pipeline)),
                    main,
                );
                let small = PlotStyle {
                    legend: false,
                    ..main
                };
                let plots = values
                    .iter()
                    .map(|(entity, name)| plot(name, &format!("/{entity}"), small))
                    .collect();
                let mut grid = container(ContainerKind::Grid, None, plots, &[]);
                if let Node::Container { grid_columns, .. } = &mut grid {
                    *grid_columns = Some(2);
                }
                container(
                    ContainerKind::Vertical,
                    Some(pipeline),
                    vec![objective, grid],
                    &[1.0, 1.0],
                )
            })
            .collect();
        container(ContainerKind::Tabs, Some("Tuning"), tabs, &[])
    }

    /// The blueprint as log messages of its own store, and the command that activates it.
    pub fn blueprint(
        &self,
        span: Option<(i64, i64)>,
    ) -> Result<(Vec<LogMsg>, BlueprintActivationCommand), Error> {
        let messages = self
            .blueprint_messages(span)
            .map_err(|e| Error::Rerun(format!("blueprint: {e}")))?;
        let blueprint_id = messages
            .iter()
            .find_map(|m| match m {
                LogMsg::SetStoreInfo(info) => Some(info.info.store_id.clone()),
                _ => None,
            })
            .ok_or_else(|| Error::Rerun("blueprint: its store has no info".into()))?;
        let activation = BlueprintActivationCommand {
            blueprint_id,
            make_active: true,
            make_default: true,
        };
        Ok((messages, activation))
    }

    fn blueprint_messages(
        &self,
        span: Option<(i64, i64)>,
    ) -> rerun::RecordingStreamResult<Vec<LogMsg>> {
        let (bp, storage) = RecordingStreamBuilder::new(crate::APPLICATION_ID)
            .blueprint()
            .memory()?;
        bp.set_time_sequence("blueprint", 0);
        let root = self.tree(span);
        root.log(&bp)?;
        bp.log(
            "viewport",
            &ViewportBlueprint::new()
                .with_root_container(RootContainer(root.id().into()))
                .with_auto_layout(false)
                .with_auto_views(false),
        )?;
        // Room for the views: the entity tree and the selection open on a click.
        for panel in ["blueprint_panel", "selection_panel"] {
            bp.log(
                panel,
                &PanelBlueprint::new().with_state(PanelState::Collapsed),
            )?;
        }
        // At the end of the run: the map shows the whole trail. The time panel is a slim bar:
        // the plots are the timeline.
        bp.log(
            "time_panel",
            &TimePanelBlueprint::new()
                .with_state(PanelState::Collapsed)
                .with_timeline(TimelineName::from(TIMELINE))
                .with_play_state(PlayState::Following),
        )?;
        Ok(storage.take())
    }

    /// Sends the blueprint to a recording stream.
    pub fn send(&self, rec: &RecordingStream, span: Option<(i64, i64)>) -> Result<(), Error> {
        let (messages, activation) = self.blueprint(span)?;
        rec.send_blueprint(messages, activation);
        Ok(())
    }
}

impl PipelineLayout {
    /// One pipeline's tab: NIS with its χ² bounds and gate decisions on the left, whatever
    /// else the pipeline estimates in a grid on the right (titles name them: no legends).
    fn tab(&self, span: Option<(i64, i64)>) -> Node {
        let p = &self.name;
        let small = PlotStyle {
            span,
            y_range: None,
            legend: false,
        };
        let nis = plot(
            &format!("{p}: NIS, χ²₁ 95 % bounds, gate decisions (clipped at the top)"),
            &format!("/{}/nis", ent::diagnostics(p)),
            PlotStyle {
                y_range: Some((0.0, NIS_AXIS_MAX)),
                ..small
            },
        );
        let mut others = Vec::new();
        if self.sharing {
            others.push(plot(
                "β per device",
                &format!("/{}", ent::sharing(p)),
                PlotStyle {
                    y_range: Some((0.0, 1.0)),
                    legend: true,
                    ..small
                },
            ));
        }
        if self.effective_sample_size {
            others.push(plot(
                "effective sample size",
                &format!("/{}", ent::effective_sample_size(p)),
                small,
            ));
        }
        if self.safety {
            others.push(plot(
                "safety: usable (1) or not (0)",
                &format!("/{}", ent::safety(p)),
                PlotStyle {
                    legend: true,
                    ..small
                },
            ));
        }
        for (entity, title) in self.bands.iter().chain(&self.lines) {
            others.push(plot(title, &format!("/{entity}"), small));
        }
        if others.is_empty() {
            return container(ContainerKind::Horizontal, Some(p), vec![nis], &[]);
        }
        let mut grid = container(ContainerKind::Grid, None, others, &[]);
        if let Node::Container { grid_columns, .. } = &mut grid {
            *grid_columns = Some(2);
        }
        container(
            ContainerKind::Horizontal,
            Some(p),
            vec![nis, grid],
            &[2.0, 3.0],
        )
    }
}

/// The events channel as a text log: level and text, without the entity path column.
fn events_view() -> Node {
    let mut events = view("TextLog", "Events", "/events");
    if let Node::View { properties, .. } = &mut events {
        let column = |kind, visible: bool| TextLogColumn {
            visible: visible.into(),
            kind,
        };
        properties.push((
            "TextLogColumns",
            Box::new(TextLogColumns::new().with_text_log_columns([
                column(TextLogColumnKind::LogLevel, true),
                column(TextLogColumnKind::Body, true),
                column(TextLogColumnKind::EntityPath, false),
            ])),
        ));
    }
    events
}
