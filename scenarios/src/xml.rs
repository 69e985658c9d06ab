//! Import of the reference control station's route XML.
//!
//! `<routes>` holds an optional `<anchors>` list (`<anchor><x/><y/><height/><id/></anchor>`) and
//! `<route>` elements (`<id/>` then `<point><x/><y/><speed/><time/></point>`). A route's role is
//! its id: 0 start route, 1 recovery route, 2 fence, 3 ignored (a drawn trace), 4–7 cutouts in id
//! order. `time` is dropped (unused in speed mode). Errors name the scenario field the XML element
//! becomes (`fence[5].x` for route 2's sixth point).

use quick_xml::Reader;
use quick_xml::events::Event;
use serde::Deserialize;

use crate::error::{Location, Problem, ScenarioError};
use crate::locate::XmlIndex;
use crate::raw::{RawAnchor, RawPoint, RawRoutePoint, RawScenario};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct XmlRoutes {
    #[serde(default)]
    anchors: Option<XmlAnchors>,
    #[serde(default, rename = "route")]
    routes: Vec<XmlRoute>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct XmlAnchors {
    #[serde(default, rename = "anchor")]
    anchors: Vec<XmlAnchor>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct XmlAnchor {
    x: String,
    y: String,
    height: String,
    id: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct XmlRoute {
    id: String,
    #[serde(default, rename = "point")]
    points: Vec<XmlPoint>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct XmlPoint {
    x: String,
    y: String,
    speed: String,
    /// Milliseconds; unused in speed mode, so dropped.
    #[serde(default, rename = "time")]
    _time: Option<String>,
}

/// The role of a route id of the reference format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Start,
    Recovery,
    Fence,
    Ignored,
    Cutout(usize),
}

fn role(id: u8) -> Option<Role> {
    match id {
        0 => Some(Role::Start),
        1 => Some(Role::Recovery),
        2 => Some(Role::Fence),
        3 => Some(Role::Ignored),
        4..=7 => Some(Role::Cutout(usize::from(id - 4))),
        _ => None,
    }
}

/// Parses reference XML into the file form of a scenario named `name`.
/// Also returns where each element starts, so that problems found later name a line.
pub(crate) fn parse_xml(
    text: &str,
    source_name: &str,
    name: &str,
) -> Result<(RawScenario, XmlIndex), ScenarioError> {
    let mut index = check_well_formed(text, source_name)?;
    let routes: XmlRoutes = quick_xml::de::from_str(text).map_err(|e| {
        ScenarioError::in_source(source_name, None, Problem::XmlSyntax(e.to_string()))
    })?;
    let by_role = assign_roles(&routes.routes);
    if let Ok(by_role) = &by_role {
        for routed in by_role {
            index.role(routed.field.clone(), routed.at);
        }
    }
    let err = |field: String, problem| {
        let mut error = ScenarioError::in_field(source_name, field.clone(), problem);
        error.place.location = index.locate(text, &field);
        error
    };
    let anchors = routes
        .anchors
        .map(|a| anchors(&a.anchors))
        .transpose()
        .map_err(|(f, p)| err(f, p))?
        .unwrap_or_default();
    let by_role = by_role.map_err(|(f, p)| err(f, p))?;
    let mut scenario = RawScenario {
        name: Some(name.to_owned()),
        description: None,
        origin: None,
        fence: Vec::new(),
        cutouts: Vec::new(),
        start_route: Vec::new(),
        recovery_route: Vec::new(),
        anchors,
        environment: Default::default(),
        vehicle: Default::default(),
        generator: Default::default(),
        campaign: Default::default(),
    };
    for (id, role, needed) in [
        (0, "start route", Role::Start),
        (1, "recovery route", Role::Recovery),
        (2, "fence", Role::Fence),
    ] {
        if !by_role.iter().any(|routed| routed.role == needed) {
            return Err(ScenarioError::in_source(
                source_name,
                None,
                Problem::MissingRoute { id, role },
            ));
        }
    }
    for routed in by_role {
        fill(&mut scenario, &routed).map_err(|(f, p)| err(f, p))?;
    }
    Ok((scenario, index))
}

/// The anchors of a reference XML file that holds only anchors (`<routes><anchors>…</anchors>
/// </routes>`; any routes in it are refused, so that an area file given by mistake says so).
pub(crate) fn parse_anchors(
    text: &str,
    source_name: &str,
) -> Result<Vec<RawAnchor>, ScenarioError> {
    let index = check_well_formed(text, source_name)?;
    let routes: XmlRoutes = quick_xml::de::from_str(text).map_err(|e| {
        ScenarioError::in_source(source_name, None, Problem::XmlSyntax(e.to_string()))
    })?;
    if !routes.routes.is_empty() {
        return Err(ScenarioError::in_source(
            source_name,
            None,
            Problem::Schema(format!(
                "an anchors file holds only <anchors>; this one has {} route(s)",
                routes.routes.len()
            )),
        ));
    }
    let list = routes.anchors.map(|a| a.anchors).unwrap_or_default();
    if list.is_empty() {
        return Err(ScenarioError::in_source(
            source_name,
            None,
            Problem::Schema("no <anchor> in <anchors>".to_owned()),
        ));
    }
    anchors(&list).map_err(|(field, problem)| {
        let mut error = ScenarioError::in_field(source_name, field.clone(), problem);
        error.place.location = index.locate(text, &field);
        error
    })
}

/// Reads every event once so that syntax errors carry a line and column, checks the root, and
/// notes where each element starts.
fn check_well_formed(text: &str, source_name: &str) -> Result<XmlIndex, ScenarioError> {
    let mut reader = Reader::from_str(text);
    let mut root_seen = false;
    let mut index = XmlIndex::default();
    let mut open: Vec<String> = Vec::new();
    loop {
        let starts_at = usize::try_from(reader.buffer_position()).unwrap_or(usize::MAX);
        let event = reader.read_event().map_err(|e| {
            let offset = usize::try_from(reader.error_position()).unwrap_or(usize::MAX);
            let location = Some(Location::of_offset(text, offset));
            ScenarioError::in_source(source_name, location, Problem::XmlSyntax(e.to_string()))
        })?;
        match &event {
            Event::Start(start) | Event::Empty(start) if !root_seen => {
                root_seen = true;
                if start.name().0 != "routes" {
                    let offset = usize::try_from(reader.buffer_position()).unwrap_or(usize::MAX);
                    let found = start.name().0.to_owned();
                    return Err(ScenarioError::in_source(
                        source_name,
                        Some(Location::of_offset(text, offset)),
                        Problem::XmlSyntax(format!(
                            "the root element is <{found}>, expected <routes>"
                        )),
                    ));
                }
            }
            _ => {}
        }
        match event {
            Event::Start(start) => {
                index.element(&open, &start, starts_at);
                open.push(start.name().0.to_owned());
            }
            Event::Empty(start) => index.element(&open, &start, starts_at),
            Event::End(_) => {
                open.pop();
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if root_seen {
        Ok(index)
    } else {
        Err(ScenarioError::in_source(
            source_name,
            None,
            Problem::XmlSyntax("no <routes> element".into()),
        ))
    }
}

type FieldProblem = (String, Problem);

fn number(text: &str, field: impl FnOnce() -> String) -> Result<f64, FieldProblem> {
    text.trim()
        .parse()
        .map_err(|_| (field(), Problem::NotANumber(text.trim().to_owned())))
}

fn anchors(list: &[XmlAnchor]) -> Result<Vec<RawAnchor>, FieldProblem> {
    list.iter()
        .enumerate()
        .map(|(i, a)| {
            let at = |name: &str| format!("anchors[{i}].{name}");
            let id =
                a.id.trim()
                    .parse()
                    .map_err(|_| (at("id"), Problem::NotANumber(a.id.trim().to_owned())))?;
            Ok(RawAnchor {
                id,
                x: number(&a.x, || at("x"))?,
                y: number(&a.y, || at("y"))?,
                height: number(&a.height, || at("height"))?,
            })
        })
        .collect()
}

/// A route with its role, the scenario field it becomes (`fence`, `cutouts[1]`) and its index in
/// the document.
struct Routed<'a> {
    role: Role,
    field: String,
    at: usize,
    route: &'a XmlRoute,
}

/// Each route with its role, field and index in the document, cutouts in id order; ignored
/// routes dropped.
fn assign_roles(routes: &[XmlRoute]) -> Result<Vec<Routed<'_>>, FieldProblem> {
    let mut seen: Vec<u8> = Vec::new();
    let mut assigned = Vec::new();
    for (i, route) in routes.iter().enumerate() {
        let text = route.id.trim();
        let field = || format!("route[{i}].id");
        let id: u8 = text
            .parse()
            .map_err(|_| (field(), Problem::UnknownRouteId(text.to_owned())))?;
        let role = role(id).ok_or_else(|| (field(), Problem::UnknownRouteId(text.to_owned())))?;
        if seen.contains(&id) {
            return Err((field(), Problem::DuplicateRouteId(id)));
        }
        seen.push(id);
        if role != Role::Ignored {
            assigned.push((role, i, route));
        }
    }
    assigned.sort_by_key(|(role, _, _)| match role {
        Role::Cutout(k) => *k,
        _ => 0,
    });
    let mut cutouts = 0;
    Ok(assigned
        .into_iter()
        .map(|(role, at, route)| {
            let field = match role {
                Role::Start => "start_route".to_owned(),
                Role::Recovery => "recovery_route".to_owned(),
                Role::Fence => "fence".to_owned(),
                // Ignored routes were dropped above.
                Role::Cutout(_) | Role::Ignored => {
                    cutouts += 1;
                    format!("cutouts[{}]", cutouts - 1)
                }
            };
            Routed {
                role,
                field,
                at,
                route,
            }
        })
        .collect())
}

fn fill(scenario: &mut RawScenario, routed: &Routed<'_>) -> Result<(), FieldProblem> {
    let (route, field) = (routed.route, routed.field.as_str());
    match routed.role {
        Role::Start => scenario.start_route = route_points(route, field)?,
        Role::Recovery => scenario.recovery_route = route_points(route, field)?,
        Role::Fence => scenario.fence = polygon(route, field)?,
        Role::Cutout(_) => scenario.cutouts.push(polygon(route, field)?),
        Role::Ignored => {}
    }
    Ok(())
}

fn route_points(route: &XmlRoute, field: &str) -> Result<Vec<RawRoutePoint>, FieldProblem> {
    route
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let at = |name: &str| format!("{field}[{i}].{name}");
            Ok(RawRoutePoint {
                x: number(&p.x, || at("x"))?,
                y: number(&p.y, || at("y"))?,
                speed: number(&p.speed, || at("speed"))?,
            })
        })
        .collect()
}

fn polygon(route: &XmlRoute, field: &str) -> Result<Vec<RawPoint>, FieldProblem> {
    route
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let at = |name: &str| format!("{field}[{i}].{name}");
            Ok(RawPoint {
                x: number(&p.x, || at("x"))?,
                y: number(&p.y, || at("y"))?,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use crate::{Problem, from_xml_str};

    fn route(id: &str, points: &[(f64, f64)]) -> String {
        let points: String = points
            .iter()
            .map(|(x, y)| {
                format!("<point><x>{x}</x><y>{y}</y><speed>0.5</speed><time>7</time></point>")
            })
            .collect();
        format!("<route><id>{id}</id>{points}</route>")
    }

    fn square(extra: &str) -> String {
        format!(
            "<routes><anchors><anchor><x>-1</x><y>-1</y><height>1</height><id>7</id></anchor>\
             </anchors>{}{}{}{extra}</routes>",
            route("2", &[(0., 0.), (10., 0.), (10., 10.), (0., 10.)]),
            route("0", &[(2., 2.), (3.5, 2.), (5., 2.)]),
            route("1", &[(2., 6.), (2., 4.5), (2., 3.2)]),
        )
    }

    #[test]
    fn anchors_from_a_file_of_their_own_are_merged_into_an_area_without_any() {
        let with = square("");
        let anchors_start = with.find("<anchors>").unwrap();
        let anchors_end = with.find("</anchors>").unwrap() + "</anchors>".len();
        let area = format!("{}{}", &with[..anchors_start], &with[anchors_end..]);
        let only = "<routes>\n<anchors>\n<anchor><x>3</x><y>4</y><height>2</height><id>50</id></anchor>\n\
                    <anchor><x>8</x><y>4</y><height>2</height><id>234</id></anchor>\n</anchors>\n</routes>";
        let loaded =
            crate::from_xml_with_anchors((&area, "area.xml"), (only, "anchors.xml"), "lot")
                .unwrap();
        let ids: Vec<u8> = loaded.scenario.anchors.iter().map(|a| a.id).collect();
        assert_eq!(ids, [50, 234]);
        assert_eq!(loaded.scenario.name, "lot");
        // The area has anchors of its own: refused, naming both files.
        let error = crate::from_xml_with_anchors((&with, "area.xml"), (only, "anchors.xml"), "lot")
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("area.xml") && error.contains("anchors.xml"),
            "{error}"
        );
        // An area file given as the anchors file: refused.
        let error = crate::from_xml_with_anchors((&area, "area.xml"), (&area, "b.xml"), "lot")
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("b.xml") && error.contains("route(s)"),
            "{error}"
        );
        // A bad number in the anchors file names its line.
        let bad = only.replace("<x>8</x>", "<x>eight</x>");
        let error = crate::from_xml_with_anchors((&area, "area.xml"), (&bad, "anchors.xml"), "lot")
            .unwrap_err();
        assert_eq!(error.field(), Some("anchors[1].x"));
        assert!(error.to_string().contains("anchors.xml:"), "{error}");
    }

    #[test]
    fn roles_come_from_route_ids_and_cutouts_keep_id_order() {
        let extra = route("7", &[(7., 7.), (8., 7.), (8., 8.)])
            + &route("3", &[(50., 50.), (60., 60.)])
            + &route("4", &[(6., 4.), (7., 4.), (7., 5.)]);
        let loaded = from_xml_str(&square(&extra), "s.xml", "square").unwrap();
        let s = loaded.scenario;
        assert_eq!(s.name, "square");
        assert_eq!(s.area.fence().vertices().len(), 4);
        assert_eq!(s.area.cutouts().len(), 2, "route 3 is ignored");
        assert_eq!(s.area.cutouts()[0].vertices()[0].x, 6.0, "route 4 first");
        assert_eq!(s.start_route.points[1].position.x, 3.5);
        assert_eq!(s.recovery_route.points[0].speed, 0.5);
        assert_eq!((s.anchors[0].id, s.anchors[0].x), (7, -1.0));
    }

    #[test]
    fn a_repeated_route_id_is_refused() {
        let extra = route("0", &[(2., 2.), (3.5, 2.)]);
        let error = from_xml_str(&square(&extra), "s.xml", "s").unwrap_err();
        assert!(matches!(error.problem, Problem::DuplicateRouteId(0)));
        assert_eq!(error.field(), Some("route[3].id"));
    }

    #[test]
    fn the_root_must_be_routes_and_unknown_elements_are_refused() {
        let error = from_xml_str("<areas></areas>", "s.xml", "s").unwrap_err();
        assert_eq!(
            error.to_string(),
            "s.xml:1:8: invalid XML: the root element is <areas>, expected <routes>"
        );
        let text = square("<colour>red</colour>");
        let error = from_xml_str(&text, "s.xml", "s").unwrap_err();
        assert!(
            error.to_string().contains("unknown field `colour`"),
            "{error}"
        );
    }

    #[test]
    fn problems_found_after_parsing_name_the_line_of_the_element() {
        let text = square("").replace("><", ">\n<");
        let line_of = |needle: &str, nth: usize| {
            text.lines()
                .enumerate()
                .filter(|(_, l)| l.contains(needle))
                .nth(nth)
                .map(|(i, _)| i + 1)
        };
        // The fence is route 2, the first route; its second point's x.
        let bad = text.replacen("<x>10</x>", "<x>ten</x>", 1);
        let error = from_xml_str(&bad, "s.xml", "s").unwrap_err();
        assert_eq!(error.field(), Some("fence[1].x"));
        assert_eq!(
            error.place.location.map(|l| l.line),
            line_of("<x>10</x>", 0)
        );
        // A problem of the whole fence (found by validation) points at its <route>.
        let crossing = text.replacen("<x>10</x>", "<x>-10</x>", 1);
        let error = from_xml_str(&crossing, "s.xml", "s").unwrap_err();
        assert_eq!(error.field(), Some("fence"));
        assert_eq!(error.place.location.map(|l| l.line), line_of("<route>", 0));
        // An anchor's field.
        let anchor = text.replace("<height>1</height>", "<height>high</height>");
        let error = from_xml_str(&anchor, "s.xml", "s").unwrap_err();
        assert_eq!(error.field(), Some("anchors[0].height"));
        assert_eq!(error.place.location.map(|l| l.line), line_of("<height>", 0));
    }

    #[test]
    fn an_anchor_id_must_fit_a_byte() {
        let text = square("").replace("<id>7</id></anchor>", "<id>-1</id></anchor>");
        let error = from_xml_str(&text, "s.xml", "s").unwrap_err();
        assert!(matches!(error.problem, Problem::AnchorIdOutOfRange(-1)));
        assert_eq!(error.field(), Some("anchors[0].id"));
    }
}
