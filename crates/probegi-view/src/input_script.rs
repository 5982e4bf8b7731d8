//! Timed input for scripted runs (`probegi view --input-script FILE`): one
//! event per line, `FRAME EVENT ARGS…`, `#` starts a comment, blank lines are
//! skipped, frames never go back. Events:
//!
//! | line | meaning |
//! |---|---|
//! | `12 key w down`, `40 key w up` | a key pressed or released from that frame on (w a s d q e: fly; r: reset the camera) |
//! | `50 key f5 down` | a viewer key pressed (in the window only): `space` pause, `n` step the clock, `v` next view, `f5` reference, `f12` screenshot |
//! | `12 mouse 30 -5` | the mouse moved 30 px right and 5 px up during frame 12 |
//! | `12 scroll 2` | two scroll-wheel steps up (faster) during frame 12 |
//!
//! An event at frame k applies before frame k renders.

use std::path::Path;

use crate::fly_camera::FlyInput;

/// A key the fly camera reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlyKey {
    /// W: forward.
    W,
    /// S: back.
    S,
    /// A: left.
    A,
    /// D: right.
    D,
    /// Q: down.
    Q,
    /// E: up.
    E,
    /// R: reset to the scene's camera (on press).
    R,
}

/// A key of the viewer's own (not the fly camera's), acted on when pressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewerKey {
    /// Space: pause or resume the scene clock.
    Pause,
    /// N: step the paused scene clock.
    Step,
    /// V: the next view.
    NextView,
    /// F5: path-trace the reference of the view.
    Reference,
    /// F12: screenshot (PNG and EXR).
    Screenshot,
}

/// One timed event.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ScriptEvent {
    /// A key pressed (`true`) or released.
    Key(FlyKey, bool),
    /// A viewer key pressed (the window's worker acts on it; the fly camera ignores it).
    Viewer(ViewerKey),
    /// Mouse motion, pixels (x right, y down).
    Mouse(f32, f32),
    /// Scroll-wheel steps (up positive).
    Scroll(f32),
}

/// A parsed script: events in frame order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InputScript {
    /// (frame, event), frames non-decreasing.
    pub events: Vec<(u32, ScriptEvent)>,
}

/// A script line that does not parse: where and why.
#[derive(Debug, thiserror::Error)]
#[error("{path}:{line}: {why}")]
pub struct ScriptError {
    /// The script's path as given.
    pub path: String,
    /// 1-based line number.
    pub line: usize,
    /// What is wrong with it.
    pub why: String,
}

impl InputScript {
    /// Reads and parses the script at `path`.
    pub fn load(path: &Path) -> Result<Self, ScriptError> {
        let text = std::fs::read_to_string(path).map_err(|e| ScriptError {
            path: path.display().to_string(),
            line: 0,
            why: format!("cannot read it: {e}"),
        })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses `text`; errors name `path` and the line.
    pub fn parse(text: &str, path: &str) -> Result<Self, ScriptError> {
        let mut events = Vec::new();
        let mut last = 0u32;
        for (i, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let err = |why: String| ScriptError { path: path.to_string(), line: i + 1, why };
            let (frame, event) = parse_line(line).map_err(err)?;
            if frame < last {
                return Err(err(format!("frame {frame} comes after frame {last}: frames never go back")));
            }
            last = frame;
            events.push((frame, event));
        }
        Ok(Self { events })
    }

    /// The first viewer key (frame and key), which only the window acts on.
    pub fn first_viewer_key(&self) -> Option<(u32, ViewerKey)> {
        self.events.iter().find_map(|(f, e)| match e {
            ScriptEvent::Viewer(k) => Some((*f, *k)),
            _ => None,
        })
    }

    /// The last frame with an event (0 for an empty script).
    pub fn last_frame(&self) -> u32 {
        self.events.last().map_or(0, |(f, _)| *f)
    }
}

fn parse_line(line: &str) -> Result<(u32, ScriptEvent), String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    let frame: u32 = words[0].parse().map_err(|_| format!("`{}` is not a frame number", words[0]))?;
    let number = |k: usize| -> Result<f32, String> {
        let w = words.get(k).ok_or_else(|| format!("`{line}`: a number is missing"))?;
        w.parse::<f32>().ok().filter(|v| v.is_finite()).ok_or_else(|| format!("`{w}` is not a finite number"))
    };
    let arity = |n: usize| {
        if words.len() == n { Ok(()) } else { Err(format!("`{line}`: expected {} words, got {}", n, words.len())) }
    };
    let event = match words.get(1).copied() {
        Some("key") => {
            arity(4)?;
            let viewer = match words[2].to_ascii_lowercase().as_str() {
                "space" => Some(ViewerKey::Pause),
                "n" => Some(ViewerKey::Step),
                "v" => Some(ViewerKey::NextView),
                "f5" => Some(ViewerKey::Reference),
                "f12" => Some(ViewerKey::Screenshot),
                _ => None,
            };
            if let Some(k) = viewer {
                return match words[3] {
                    "down" => Ok((frame, ScriptEvent::Viewer(k))),
                    "up" => Err(format!("`{line}`: viewer keys act when pressed; script them `down` only")),
                    s => Err(format!("`{s}`: a key goes `down` or `up`")),
                };
            }
            let key = match words[2].to_ascii_lowercase().as_str() {
                "w" => FlyKey::W,
                "s" => FlyKey::S,
                "a" => FlyKey::A,
                "d" => FlyKey::D,
                "q" => FlyKey::Q,
                "e" => FlyKey::E,
                "r" => FlyKey::R,
                k => return Err(format!("unknown key `{k}` (w a s d q e r; in the window also space n v f5 f12)")),
            };
            let down = match words[3] {
                "down" => true,
                "up" => false,
                s => return Err(format!("`{s}`: a key goes `down` or `up`")),
            };
            ScriptEvent::Key(key, down)
        }
        Some("mouse") => {
            arity(4)?;
            ScriptEvent::Mouse(number(2)?, number(3)?)
        }
        Some("scroll") => {
            arity(3)?;
            ScriptEvent::Scroll(number(2)?)
        }
        Some(w) => return Err(format!("unknown event `{w}` (key, mouse, scroll)")),
        None => return Err(format!("`{line}`: an event must follow the frame")),
    };
    Ok((frame, event))
}

/// The keys held and the motion of the current frame, fed event by event.
#[derive(Clone, Copy, Debug, Default)]
pub struct InputState {
    /// What the fly camera reads this frame.
    pub fly: FlyInput,
    /// R was pressed this frame.
    pub reset: bool,
}

impl InputState {
    /// Applies one event.
    pub fn apply(&mut self, event: ScriptEvent) {
        match event {
            ScriptEvent::Key(key, down) => match key {
                FlyKey::W => self.fly.forward = down,
                FlyKey::S => self.fly.back = down,
                FlyKey::A => self.fly.left = down,
                FlyKey::D => self.fly.right = down,
                FlyKey::Q => self.fly.down = down,
                FlyKey::E => self.fly.up = down,
                FlyKey::R => self.reset |= down,
            },
            ScriptEvent::Mouse(dx, dy) => self.fly.look_px += glam::Vec2::new(dx, dy),
            ScriptEvent::Scroll(s) => self.fly.scroll_steps += s,
            ScriptEvent::Viewer(_) => {}
        }
    }

    /// After a frame: motion and presses are per frame, held keys stay.
    pub fn end_frame(&mut self) {
        self.fly.look_px = glam::Vec2::ZERO;
        self.fly.scroll_steps = 0.0;
        self.reset = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_script_parses_into_timed_events() {
        let text = "# fly in\n0 key w down\n\n10 mouse 30 -5  # turn\n10 scroll 2\n40 key W up\n";
        let s = InputScript::parse(text, "fly.txt").expect("parses");
        assert_eq!(
            s.events,
            vec![
                (0, ScriptEvent::Key(FlyKey::W, true)),
                (10, ScriptEvent::Mouse(30.0, -5.0)),
                (10, ScriptEvent::Scroll(2.0)),
                (40, ScriptEvent::Key(FlyKey::W, false)),
            ]
        );
        assert_eq!(s.last_frame(), 40);
    }

    #[test]
    fn bad_lines_name_the_file_and_the_line() {
        let cases = [
            ("x key w down", "not a frame number"),
            ("1 key z down", "unknown key"),
            ("1 key w sideways", "`down` or `up`"),
            ("1 mouse 3", "expected 4 words"),
            ("1 mouse 3 nan", "not a finite number"),
            ("1 jump", "unknown event"),
            ("5 scroll 1\n4 scroll 1", "frames never go back"),
        ];
        for (text, why) in cases {
            let e = InputScript::parse(text, "s.txt").expect_err(text).to_string();
            assert!(e.starts_with("s.txt:") && e.contains(why), "{text}: {e}");
        }
        let e = InputScript::parse("0 key w down\n3 key", "s.txt").expect_err("arity").to_string();
        assert!(e.starts_with("s.txt:2:"), "{e}");
    }

    #[test]
    fn held_keys_stay_and_motion_lasts_one_frame() {
        let mut st = InputState::default();
        st.apply(ScriptEvent::Key(FlyKey::W, true));
        st.apply(ScriptEvent::Mouse(3.0, 4.0));
        st.apply(ScriptEvent::Key(FlyKey::R, true));
        assert!(st.fly.forward && st.reset && st.fly.look_px == glam::Vec2::new(3.0, 4.0));
        st.end_frame();
        assert!(st.fly.forward && !st.reset && st.fly.look_px == glam::Vec2::ZERO);
    }
}
