//! The reply envelope (`protocol::Reply`): what the device writes reads back as the same
//! reply, body lines are told from its end, an `err` without a known code is refused.

use gms_core::protocol::{BadReply, ErrorCode, Reply};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// Any `ok TEXT` or `err CODE REASON` of printable text reads back as written.
    #[test]
    fn a_written_reply_reads_back_the_same(
        ok in any::<bool>(),
        code in prop::sample::select(ErrorCode::ALL.to_vec()),
        text in "[ -~]{0,60}",
    ) {
        // Trailing spaces are not kept by a line-based reader: text as the device writes it.
        let text = text.trim_end();
        let (ok_text, reason) = (text.trim_start(), text);
        let r = if ok { Reply::Ok(ok_text) } else { Reply::Err(code, reason) };
        let line = r.to_string();
        prop_assert!(!line.contains('\n'));
        prop_assert_eq!(Reply::parse(&line), Ok(Some(r)));
    }

    /// A line that neither starts with `ok` nor `err` is a body line.
    #[test]
    fn other_lines_are_the_body(line in "[ -~]{0,60}") {
        prop_assume!(!line.starts_with("ok") && !line.starts_with("err"));
        prop_assert_eq!(Reply::parse(&line), Ok(None));
    }
}

#[test]
fn codes_are_the_protocols_numbers() {
    assert_eq!(ErrorCode::ALL.len(), 9);
    for (n, c) in (1u8..=9).zip(ErrorCode::ALL) {
        assert_eq!(c as u8, n);
        assert_eq!(ErrorCode::from_code(n), Some(c));
    }
    assert_eq!(ErrorCode::from_code(0), None);
    assert_eq!(ErrorCode::from_code(10), None);
    assert_eq!(
        Reply::parse("err 8 disable before save"),
        Ok(Some(Reply::Err(ErrorCode::Refused, "disable before save")))
    );
    assert_eq!(Reply::parse("ok"), Ok(Some(Reply::Ok(""))));
    assert_eq!(Reply::parse("ok 0.49\r"), Ok(Some(Reply::Ok("0.49"))));
    // An `err` without a code the protocol has: refused, not a body line (it ends a reply).
    for bad in ["err", "err 99 what", "err x y", "err  8 double space"] {
        assert_eq!(Reply::parse(bad), Err(BadReply), "{bad}");
    }
    // `okay` and `error…` are body text, not an end.
    assert_eq!(Reply::parse("okay"), Ok(None));
    assert_eq!(Reply::parse("errata"), Ok(None));
}
