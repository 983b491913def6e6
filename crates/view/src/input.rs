//! What a person does, as the view core understands it: keys by their role ([`Key`]), drags,
//! the wheel, a new window size ([`Event`]); and scripts of them ([`Script`]), for viewers
//! without a person (tests, benchmarks). Front ends map their own key codes to [`Key`].

use std::fmt;

/// A key by what it does (the window and the page map W, A, S, D, arrows, Q, E, ... to these).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Key {
    /// W, up arrow.
    Forward,
    /// S, down arrow.
    Back,
    /// A, left arrow.
    Left,
    /// D, right arrow.
    Right,
    /// E.
    Up,
    /// Q.
    Down,
    /// R: back to the default view.
    Reset,
    /// F: frame the whole model.
    Frame,
    /// P: save a screenshot.
    Screenshot,
    /// C: the next built-in shader.
    NextShader,
    /// K: the sky (environment light) on or off.
    ToggleSky,
    /// H: the help text on or off.
    Help,
    /// I: the statistics line on or off.
    Info,
    /// X: the picked component X-rayed (see-through) or not.
    XRay,
    /// V: hide the picked component.
    Hide,
    /// B: show only the picked component, or everything again.
    Isolate,
    /// N: a section plane through the middle of the picked wall, cutting away the eye's side.
    Section,
    /// ]: the last section plane moves on (it cuts more away).
    CutMore,
    /// [: the last section plane moves back (it cuts less).
    CutLess,
    /// U: show everything (no hidden, X-rayed or isolated components, no sections).
    ShowAll,
    /// Escape.
    Quit,
}

impl Key {
    /// The keys a person presses for it, as the help text names them.
    pub fn names(self) -> &'static str {
        match self {
            Key::Forward => "W / Up",
            Key::Back => "S / Down",
            Key::Left => "A / Left",
            Key::Right => "D / Right",
            Key::Up => "E",
            Key::Down => "Q",
            Key::Reset => "R",
            Key::Frame => "F",
            Key::Screenshot => "P",
            Key::NextShader => "C",
            Key::ToggleSky => "K",
            Key::Help => "H",
            Key::Info => "I",
            Key::XRay => "X",
            Key::Hide => "V",
            Key::Isolate => "B",
            Key::Section => "N",
            Key::CutMore => "]",
            Key::CutLess => "[",
            Key::ShowAll => "U",
            Key::Quit => "Esc",
        }
    }

    /// Every key, in the help text's order.
    pub const ALL: [Key; 21] = [
        Key::Forward,
        Key::Back,
        Key::Left,
        Key::Right,
        Key::Up,
        Key::Down,
        Key::Reset,
        Key::Frame,
        Key::Screenshot,
        Key::NextShader,
        Key::ToggleSky,
        Key::Help,
        Key::Info,
        Key::XRay,
        Key::Hide,
        Key::Isolate,
        Key::Section,
        Key::CutMore,
        Key::CutLess,
        Key::ShowAll,
        Key::Quit,
    ];

    /// What it does, for the help text.
    pub fn what(self) -> &'static str {
        match self {
            Key::Forward => "fly forward",
            Key::Back => "fly back",
            Key::Left => "fly left",
            Key::Right => "fly right",
            Key::Up => "fly up",
            Key::Down => "fly down",
            Key::Reset => "reset to the default view",
            Key::Frame => "frame the whole model",
            Key::Screenshot => "save a screenshot (PNG)",
            Key::NextShader => "next shader",
            Key::ToggleSky => "sky light on / off",
            Key::Help => "this help",
            Key::Info => "statistics line on / off",
            Key::XRay => "X-ray the picked part on / off",
            Key::Hide => "hide the picked part",
            Key::Isolate => "show only the picked part / all",
            Key::Section => "section through the picked wall (eye's side cut)",
            Key::CutMore => "move the last section on (cut more)",
            Key::CutLess => "move the last section back (cut less)",
            Key::ShowAll => "show everything (no hide, X-ray, section)",
            Key::Quit => "quit",
        }
    }

    /// The key a script names (`forward`, `back`, ... as in [`Key::ALL`], lower case).
    pub fn parse(s: &str) -> Option<Key> {
        Key::ALL.into_iter().find(|k| format!("{k:?}").eq_ignore_ascii_case(s))
    }

    /// Keys that act once when pressed (the others act while held).
    pub fn is_action(self) -> bool {
        !matches!(self, Key::Forward | Key::Back | Key::Left | Key::Right | Key::Up | Key::Down)
    }
}

/// The help text, a line a key, plus the mouse.
pub fn help_lines() -> Vec<String> {
    let mut v: Vec<String> = Key::ALL.iter().map(|k| format!("{:<10} {}", k.names(), k.what())).collect();
    v.insert(6, format!("{:<10} {}", "drag", "look around"));
    v.insert(7, format!("{:<10} {}", "wheel", "flying speed"));
    v.insert(8, format!("{:<10} {}", "click", "pick: name, point, thickness (highlighted)"));
    v.insert(9, format!("{:<10} {}", "shift+clk", "measure from the last pick"));
    v
}

/// Something a person did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// A key went down (`true`) or up.
    Key(Key, bool),
    /// The mouse moved by (dx, dy) pixels with its button held.
    Drag(f32, f32),
    /// Wheel notches (up positive).
    Wheel(f32),
    /// The view is now this many pixels.
    Resize(u32, u32),
    /// A click at (x, y) in the view's pixels: pick what lies there; `true` (shift held)
    /// also measures from the last pick.
    Click(f32, f32, bool),
}

/// One step of a [`Script`].
#[derive(Clone, Debug, PartialEq)]
pub enum Step {
    /// An input event.
    Input(Event),
    /// Render this many frames.
    Frames(u32),
}

/// A recorded session: input events and frames, one a line.
///
/// ```text
/// # comments and blank lines are skipped
/// frames 4          # render 4 frames
/// key forward down  # a key by its role (see megaray view --help)
/// frames 15
/// key forward up
/// drag 40 -10       # the mouse dragged 40 pixels right, 10 up
/// wheel 2           # two notches up
/// resize 320 240
/// click 160 120     # pick under pixel (160, 120); `click X Y measure`: shift-click
/// key screenshot down
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Script {
    pub steps: Vec<Step>,
}

/// A line of a script that does not parse.
#[derive(Clone, Debug, PartialEq)]
pub struct ScriptError {
    pub line: usize,
    pub msg: String,
}

impl fmt::Display for ScriptError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.msg)
    }
}

impl Script {
    /// Parses a script ([`Script`]'s format).
    pub fn parse(text: &str) -> Result<Script, ScriptError> {
        let mut steps = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let err = |msg: String| ScriptError { line: i + 1, msg };
            let w: Vec<&str> = line.split_whitespace().collect();
            let num = |s: &str| s.parse::<f32>().ok().filter(|x| x.is_finite());
            let step = match w.as_slice() {
                ["frames", n] => Step::Frames(
                    n.parse().ok().filter(|&n| n <= 1_000_000).ok_or_else(|| err(format!("bad frame count `{n}`")))?,
                ),
                ["key", k, d @ ("down" | "up")] => {
                    let key = Key::parse(k).ok_or_else(|| err(format!("unknown key `{k}`")))?;
                    Step::Input(Event::Key(key, *d == "down"))
                }
                ["drag", x, y] => match (num(x), num(y)) {
                    (Some(x), Some(y)) => Step::Input(Event::Drag(x, y)),
                    _ => return Err(err(format!("bad drag `{line}`"))),
                },
                ["wheel", n] => Step::Input(Event::Wheel(num(n).ok_or_else(|| err(format!("bad wheel `{n}`")))?)),
                ["resize", w, h] => match (w.parse::<u32>(), h.parse::<u32>()) {
                    (Ok(w), Ok(h)) if (1..=16384).contains(&w) && (1..=16384).contains(&h) => {
                        Step::Input(Event::Resize(w, h))
                    }
                    _ => return Err(err(format!("bad size `{line}`"))),
                },
                ["click", x, y, rest @ ..] if rest.is_empty() || rest == ["measure"] => match (num(x), num(y)) {
                    (Some(x), Some(y)) => Step::Input(Event::Click(x, y, !rest.is_empty())),
                    _ => return Err(err(format!("bad click `{line}`"))),
                },
                _ => {
                    return Err(err(format!(
                        "cannot read `{line}` (frames N, key NAME down|up, drag DX DY, wheel N, resize W H, click X Y [measure])"
                    )))
                }
            };
            steps.push(step);
        }
        Ok(Script { steps })
    }
}
