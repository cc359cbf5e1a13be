//! [`WireFrame`]: an `inbetween.v1.Frame` already encoded by its playback.
//!
//! The generated gRPC server sends `WireFrame` where the proto says `Frame`
//! (see `build.rs`), and tonic's codec asks it to encode itself: it copies
//! its bytes. So a tick is encoded once for all its gRPC viewers instead of
//! once per viewer. The bytes are a complete `Frame` message body, so what
//! goes on the wire is exactly what the proto describes.

use bytes::{Buf, BufMut, Bytes, BytesMut};
use prost::encoding::{DecodeContext, WireType, decode_varint, encode_key, encode_varint};
use prost::{DecodeError, Message};

use crate::wire::proto::pb;

/// The encoded body of one `inbetween.v1.Frame`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WireFrame(pub Bytes);

impl WireFrame {
    /// The frame these bytes encode.
    ///
    /// # Errors
    /// The bytes are not a valid `Frame` (they always are when the engine
    /// made them).
    pub fn decode_frame(&self) -> Result<pb::Frame, DecodeError> {
        pb::Frame::decode(self.0.clone())
    }
}

impl Message for WireFrame {
    fn encode_raw(&self, buf: &mut impl BufMut) {
        buf.put_slice(&self.0);
    }

    /// Keeps each field as raw bytes, so decoding and re-encoding is exact.
    fn merge_field(
        &mut self,
        tag: u32,
        wire_type: WireType,
        buf: &mut impl Buf,
        _ctx: DecodeContext,
    ) -> Result<(), DecodeError> {
        let mut out = BytesMut::from(std::mem::take(&mut self.0));
        encode_key(tag, wire_type, &mut out);
        let copy = |n: usize, buf: &mut dyn Buf, out: &mut BytesMut| {
            if buf.remaining() < n {
                return Err(decode_error("buffer underflow"));
            }
            out.put(buf.take(n));
            Ok(())
        };
        match wire_type {
            WireType::Varint => encode_varint(decode_varint(buf)?, &mut out),
            WireType::SixtyFourBit => copy(8, buf, &mut out)?,
            WireType::ThirtyTwoBit => copy(4, buf, &mut out)?,
            WireType::LengthDelimited => {
                let len = decode_varint(buf)?;
                encode_varint(len, &mut out);
                copy(usize::try_from(len).map_err(|_| decode_error("length overflow"))?, buf, &mut out)?;
            }
            WireType::StartGroup | WireType::EndGroup => return Err(decode_error("groups are not used")),
        }
        self.0 = out.freeze();
        Ok(())
    }

    fn encoded_len(&self) -> usize {
        self.0.len()
    }

    fn clear(&mut self) {
        self.0 = Bytes::new();
    }
}

#[allow(deprecated)] // prost keeps `DecodeError::new` public for hand-written messages like this one.
fn decode_error(what: &'static str) -> DecodeError {
    DecodeError::new(what)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wire_frame_encodes_as_its_bytes_and_decodes_back() {
        let frame = pb::Frame {
            seq: 3,
            clip_time: 0.5,
            sent_at_unix_nanos: 42,
            dropped: 1,
            events: vec![pb::Event { time: 0.5, name: "hit".into() }],
            pose: Some(pb::Pose { translations: vec![1.0, 2.0, 3.0], time: 0.5, ..Default::default() }),
            ..Default::default()
        };
        let bytes = Bytes::from(frame.encode_to_vec());
        let wire = WireFrame(bytes.clone());
        assert_eq!(wire.encode_to_vec(), bytes);
        assert_eq!(wire.encoded_len(), bytes.len());
        let back = WireFrame::decode(bytes.clone()).unwrap();
        assert_eq!(back.decode_frame().unwrap(), frame);
    }
}
