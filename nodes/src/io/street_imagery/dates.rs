//! Capture times: ISO 8601 (UTC) to and from milliseconds since 1970, through chrono's calendar.

use chrono::{DateTime, Datelike, NaiveDateTime, Timelike, Utc};

/// ISO 8601 (UTC, milliseconds) of a time in milliseconds since 1970, e.g.
/// `2024-05-01T12:34:56.789Z`; times beyond chrono's range (±262,000 years) are clamped to it.
pub fn iso_from_ms(ms: i64) -> String {
    let t = DateTime::from_timestamp_millis(ms).unwrap_or(if ms < 0 {
        DateTime::<Utc>::MIN_UTC
    } else {
        DateTime::<Utc>::MAX_UTC
    });
    // Not chrono's `%Y`: it writes a year before 0 with four digits after the sign, where this
    // has always written four characters with the sign (`-005`).
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}Z",
        t.year(),
        t.month(),
        t.day(),
        t.hour(),
        t.minute(),
        t.second(),
        t.timestamp_subsec_millis()
    )
}

/// Milliseconds since 1970 of `YYYY-MM-DDTHH:MM:SS[.fff][Z]` (UTC), the inverse of
/// [`iso_from_ms`]; digits of the fraction past the milliseconds are dropped.
pub fn ms_from_iso(s: &str) -> Option<i64> {
    let s = s.strip_suffix('Z').unwrap_or(s);
    let t = NaiveDateTime::parse_from_str(s, "%Y-%m-%dT%H:%M:%S%.f").ok()?;
    Some(t.and_utc().timestamp_millis())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_times_round_trip() {
        assert_eq!(iso_from_ms(0), "1970-01-01T00:00:00.000Z");
        assert_eq!(iso_from_ms(951_782_400_000), "2000-02-29T00:00:00.000Z");
        for ms in [0, 1_714_566_896_789, 951_782_400_000, -86_400_001] {
            assert_eq!(ms_from_iso(&iso_from_ms(ms)), Some(ms), "{ms}");
        }
    }
}
