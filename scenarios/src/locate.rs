//! Where a field path (`fence[3].x`, `campaign.speed_kmh.max`, `anchors[2].id`) is written in the
//! source text, so that a problem found after parsing (a crossing fence edge, a duplicate anchor
//! id) still names a line and column.
//!
//! TOML is walked with the `toml` crate's spanned document; the reference XML with an index of
//! element positions taken while checking that it is well formed, and the role each route got
//! (route id 2 is the fence, and so on). A path that goes deeper than the source (a vertex of a
//! polygon written on one line) is located at the deepest part found.

use quick_xml::events::BytesStart;
use toml::de::{DeTable, DeValue};

use crate::error::Location;

/// One step of a field path.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Step<'a> {
    Key(&'a str),
    Index(usize),
}

/// `fence[3].x` → `fence`, `3`, `x`; `None` for a path this module does not write.
fn steps(field: &str) -> Option<Vec<Step<'_>>> {
    let mut steps = Vec::new();
    for part in field.split('.') {
        let (key, mut rest) = match part.find('[') {
            Some(at) => part.split_at(at),
            None => (part, ""),
        };
        if key.is_empty() || key.contains(']') {
            return None;
        }
        steps.push(Step::Key(key));
        while let Some(open) = rest.strip_prefix('[') {
            let close = open.find(']')?;
            steps.push(Step::Index(open[..close].parse().ok()?));
            rest = &open[close + 1..];
        }
        if !rest.is_empty() {
            return None;
        }
    }
    Some(steps)
}

/// The start of `field` in TOML `text`, or of its deepest part that is written there.
pub(crate) fn in_toml(text: &str, field: &str) -> Option<Location> {
    let document = DeTable::parse(text).ok()?;
    let mut table = Some(document.get_ref());
    let mut value: Option<&DeValue<'_>> = None;
    let mut found = None;
    for step in steps(field)? {
        let next = match (step, table, value) {
            (Step::Key(key), Some(t), _) => t.iter().find(|(k, _)| k.get_ref() == key).map(|e| e.1),
            (Step::Index(i), _, Some(DeValue::Array(items))) => items.get(i),
            _ => None,
        };
        let Some(next) = next else { break };
        found = Some(next.span().start);
        value = Some(next.get_ref());
        table = match next.get_ref() {
            DeValue::Table(t) => Some(t),
            _ => None,
        };
    }
    found.map(|offset| Location::of_offset(text, offset))
}

/// Where the elements of a reference route XML start, in document order.
#[derive(Debug, Default)]
pub(crate) struct XmlIndex {
    routes: Vec<Element>,
    anchors: Vec<Element>,
    /// Scenario field (`fence`, `cutouts[1]`, `start_route`) → index of the `<route>` it came from.
    roles: Vec<(String, usize)>,
}

/// An element's start, its children's starts by name, and its nested items (`<point>`s).
#[derive(Debug, Default)]
struct Element {
    start: usize,
    children: Vec<(String, usize)>,
    items: Vec<Element>,
}

impl Element {
    fn at(start: usize) -> Self {
        Element {
            start,
            ..Element::default()
        }
    }

    fn child(&self, name: &str) -> Option<usize> {
        self.children.iter().find(|(n, _)| n == name).map(|c| c.1)
    }
}

impl XmlIndex {
    /// Notes the element `tag` starting at byte `offset`, inside the open elements `open`
    /// (outermost first, the root included).
    pub(crate) fn element(&mut self, open: &[String], tag: &BytesStart<'_>, offset: usize) {
        let name = tag.name().0.to_owned();
        let path: Vec<&str> = open.iter().map(String::as_str).collect();
        match path.as_slice() {
            ["routes"] if name == "route" => self.routes.push(Element::at(offset)),
            ["routes", "anchors"] if name == "anchor" => self.anchors.push(Element::at(offset)),
            ["routes", "route"] if name == "point" => {
                if let Some(route) = self.routes.last_mut() {
                    route.items.push(Element::at(offset));
                }
            }
            ["routes", "route"] => {
                if let Some(route) = self.routes.last_mut() {
                    route.children.push((name, offset));
                }
            }
            ["routes", "route", "point"] => {
                if let Some(point) = self.routes.last_mut().and_then(|r| r.items.last_mut()) {
                    point.children.push((name, offset));
                }
            }
            ["routes", "anchors", "anchor"] => {
                if let Some(anchor) = self.anchors.last_mut() {
                    anchor.children.push((name, offset));
                }
            }
            _ => {}
        }
    }

    /// Records that the `<route>` at `index` (document order) became scenario field `field`.
    pub(crate) fn role(&mut self, field: String, index: usize) {
        self.roles.push((field, index));
    }

    /// The start of `field` in the XML `text`, or of its deepest part that is written there.
    pub(crate) fn locate(&self, text: &str, field: &str) -> Option<Location> {
        let steps = steps(field)?;
        let (element, rest) = match steps.as_slice() {
            [Step::Key("anchors"), Step::Index(i), rest @ ..] => (self.anchors.get(*i)?, rest),
            [Step::Key("route"), Step::Index(i), rest @ ..] => (self.routes.get(*i)?, rest),
            [Step::Key("cutouts"), Step::Index(j), rest @ ..] => {
                (self.route_of(&format!("cutouts[{j}]"))?, rest)
            }
            [Step::Key(key), rest @ ..] => (self.route_of(key)?, rest),
            _ => return None,
        };
        let offset = match rest {
            [Step::Index(k), Step::Key(child), ..] => element
                .items
                .get(*k)
                .map(|point| point.child(child).unwrap_or(point.start)),
            [Step::Index(k), ..] => element.items.get(*k).map(|point| point.start),
            [Step::Key(child), ..] => element.child(child),
            [] => None,
        }
        .unwrap_or(element.start);
        Some(Location::of_offset(text, offset))
    }

    fn route_of(&self, field: &str) -> Option<&Element> {
        let (_, index) = self.roles.iter().find(|(f, _)| f == field)?;
        self.routes.get(*index)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_split_into_keys_and_indices() {
        use Step::{Index, Key};
        assert_eq!(
            steps("cutouts[1][2].x"),
            Some(vec![Key("cutouts"), Index(1), Index(2), Key("x")])
        );
        assert_eq!(
            steps("campaign.speed_kmh.max"),
            Some(vec![Key("campaign"), Key("speed_kmh"), Key("max")])
        );
        assert_eq!(steps("fence[x]"), None);
        assert_eq!(steps("fence]"), None);
    }

    #[test]
    fn toml_fields_are_found_down_to_the_deepest_written_part() {
        let text = "name = \"a\"\nfence = [\n  { x = 0.0, y = 0.0 },\n  { x = 1.0, y = 0.0 },\n]\n\n[campaign]\nspeed_kmh = { min = 3.0, max = 40.0 }\n";
        let at = |field| in_toml(text, field).map(|l| (l.line, l.column));
        assert_eq!(at("fence"), Some((2, 9)));
        assert_eq!(at("fence[1]"), Some((4, 3)));
        assert_eq!(at("fence[1].y"), Some((4, 18)));
        assert_eq!(at("campaign.speed_kmh.max"), Some((8, 32)));
        // Deeper than written: the deepest part found.
        assert_eq!(at("fence[7].x"), Some((2, 9)));
        assert_eq!(at("anchors[0]"), None);
    }
}
