//! Terminal-command text handling as the firmware does it: tokens, `%d`/`%f` scanning, limits.

/// The firmware reads at most this many tokens.
pub const MAX_TOKENS: usize = 64;

/// Splits a command text into tokens on spaces only (tabs and newlines stay inside tokens); runs
/// of spaces separate like one; at most [`MAX_TOKENS`] tokens.
pub fn tokenize(text: &str) -> Vec<&str> {
    text.split(' ')
        .filter(|t| !t.is_empty())
        .take(MAX_TOKENS)
        .collect()
}

/// `sscanf(text, "%d")`: optional leading whitespace, sign and decimal digits; `None` when no
/// digit is found; out-of-range values saturate.
pub fn scan_i32(text: &str) -> Option<i32> {
    let t = text.trim_start();
    let (negative, digits) = split_sign(t);
    let end = digits
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(digits.len());
    if end == 0 {
        return None;
    }
    let magnitude = digits[..end]
        .bytes()
        .fold(0i64, |acc, d| (acc * 10 + i64::from(d - b'0')).min(1 << 40));
    let value = if negative { -magnitude } else { magnitude };
    Some(value.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32)
}

/// `sscanf(text, "%f")`: the longest prefix that is a decimal float (with optional exponent), or
/// `inf`/`nan`; `None` when there is none.
pub fn scan_f32(text: &str) -> Option<f32> {
    let t = text.trim_start();
    let (_, rest) = split_sign(t);
    let lower = rest.to_ascii_lowercase();
    let sign_len = t.len() - rest.len();
    for word in ["infinity", "inf", "nan"] {
        if lower.starts_with(word) {
            return t[..sign_len + word.len()].parse::<f32>().ok();
        }
    }
    let end = sign_len + decimal_prefix_len(rest);
    if end == sign_len {
        return None;
    }
    t[..end].parse::<f32>().ok()
}

fn split_sign(t: &str) -> (bool, &str) {
    match t.as_bytes().first() {
        Some(b'-') => (true, &t[1..]),
        Some(b'+') => (false, &t[1..]),
        _ => (false, t),
    }
}

/// Length of the longest prefix of the form `digits[.digits][e[sign]digits]` with a digit somewhere
/// before the exponent.
fn decimal_prefix_len(s: &str) -> usize {
    let b = s.as_bytes();
    let mut i = b.iter().take_while(|c| c.is_ascii_digit()).count();
    let mut mantissa_digits = i;
    if b.get(i) == Some(&b'.') {
        let frac = b[i + 1..].iter().take_while(|c| c.is_ascii_digit()).count();
        mantissa_digits += frac;
        i += 1 + frac;
    }
    if mantissa_digits == 0 {
        return 0;
    }
    if matches!(b.get(i), Some(b'e' | b'E')) {
        let mut j = i + 1;
        if matches!(b.get(j), Some(b'+' | b'-')) {
            j += 1;
        }
        let exp = b[j.min(b.len())..]
            .iter()
            .take_while(|c| c.is_ascii_digit())
            .count();
        if exp > 0 {
            i = j + exp;
        }
    }
    i
}

/// Cuts a PRINTF text to the firmware's limit (on a character boundary).
pub fn truncate_printf(mut text: String, max_chars: usize) -> String {
    if text.len() > max_chars {
        let mut cut = max_chars;
        while !text.is_char_boundary(cut) {
            cut -= 1;
        }
        text.truncate(cut);
    }
    text
}

/// Reply to an empty command text.
pub const NO_COMMAND: &str = "No command received\n";

/// Reply to an unknown command.
pub fn invalid_command(cmd: &str) -> String {
    format!("Invalid command: {cmd}\ntype help to list all available commands\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_split_on_spaces_only() {
        assert_eq!(
            tokenize("fi_add_fault  px OFFSET"),
            ["fi_add_fault", "px", "OFFSET"]
        );
        assert_eq!(tokenize("fi_clear_faults\n"), ["fi_clear_faults\n"]);
        assert_eq!(tokenize("a\tb"), ["a\tb"]);
        assert!(tokenize("   ").is_empty());
        assert_eq!(tokenize(&"x ".repeat(100)).len(), 64);
    }

    #[test]
    fn scanning_follows_c_sscanf() {
        assert_eq!(scan_i32("15"), Some(15));
        assert_eq!(scan_i32("-3x"), Some(-3));
        assert_eq!(scan_i32("1.9"), Some(1));
        assert_eq!(scan_i32("abc"), None);
        assert_eq!(scan_i32("99999999999999"), Some(i32::MAX));
        assert_eq!(scan_f32("2.0"), Some(2.0));
        assert_eq!(scan_f32("2"), Some(2.0));
        assert_eq!(scan_f32("-1.5e2m"), Some(-150.0));
        assert_eq!(scan_f32(".5"), Some(0.5));
        assert_eq!(scan_f32("1e"), Some(1.0));
        assert_eq!(scan_f32("x"), None);
        assert_eq!(scan_f32("."), None);
        assert!(scan_f32("nan").is_some_and(f32::is_nan));
        assert_eq!(scan_f32("-inf"), Some(f32::NEG_INFINITY));
    }

    #[test]
    fn printf_text_is_cut_at_the_limit() {
        assert_eq!(truncate_printf("abcdef".into(), 4), "abcd");
        assert_eq!(truncate_printf("ab".into(), 4), "ab");
        assert_eq!(truncate_printf("aé".into(), 2), "a");
    }
}
