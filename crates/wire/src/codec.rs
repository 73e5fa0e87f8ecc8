//! The frame layer every protocol implements, and the deframer that drives it.
//!
//! A [`Codec`] decodes at most one frame from the front of a buffer: `Ok(None)` when more
//! bytes are needed, `Ok(Some((frame, consumed)))`, or an error that says how many bytes to
//! drop before trying again ([`Resync`]). The [`Deframer`] owns the buffer and applies that
//! rule, so splitting the input at any point gives the same frames.

/// An error after which the decoder can resynchronise by dropping bytes.
pub trait Resync {
    /// How many bytes at the front of the buffer to drop (at least 1).
    fn drop_len(&self) -> usize;
}

/// One protocol's frame layer.
pub trait Codec {
    /// A decoded frame.
    type Frame;
    /// Why the front of the buffer is not a frame.
    type Error: Resync;

    /// Decodes at most one frame from the front of `buf`.
    ///
    /// Never panics, whatever `buf` holds.
    fn decode(&self, buf: &[u8]) -> Result<Option<(Self::Frame, usize)>, Self::Error>;

    /// Appends the bytes of `frame` to `out`.
    fn encode(&self, frame: &Self::Frame, out: &mut Vec<u8>);
}

/// What the deframer found in the stream, with the bytes it came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Chunk<F, E> {
    /// A frame and the bytes it was decoded from.
    Frame {
        /// The decoded frame.
        frame: F,
        /// Its bytes on the wire.
        raw: Vec<u8>,
    },
    /// Bytes that were dropped, and why.
    Skipped {
        /// Why the bytes are not a frame.
        error: E,
        /// The dropped bytes.
        raw: Vec<u8>,
    },
}

type Decoded<C> = Result<<C as Codec>::Frame, <C as Codec>::Error>;

/// Turns a byte stream into frames, dropping what cannot be decoded.
#[derive(Debug, Clone)]
pub struct Deframer<C: Codec> {
    codec: C,
    buf: Vec<u8>,
}

impl<C: Codec> Deframer<C> {
    /// A deframer with an empty buffer.
    pub fn new(codec: C) -> Self {
        Self {
            codec,
            buf: Vec::new(),
        }
    }

    /// Appends bytes received from the line.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// The next frame, or the error for bytes just dropped, or `None` when more bytes are
    /// needed. Call it until it returns `None` after every [`push`](Self::push).
    pub fn next_frame(&mut self) -> Option<Result<C::Frame, C::Error>> {
        let (result, consumed) = self.decode_front()?;
        self.buf.drain(..consumed);
        Some(result)
    }

    /// Like [`next_frame`](Self::next_frame), with the bytes of each frame or of each run of
    /// dropped bytes (for annotated dumps of captures).
    pub fn next_chunk(&mut self) -> Option<Chunk<C::Frame, C::Error>> {
        let (result, consumed) = self.decode_front()?;
        let raw: Vec<u8> = self.buf.drain(..consumed).collect();
        Some(match result {
            Ok(frame) => Chunk::Frame { frame, raw },
            Err(error) => Chunk::Skipped { error, raw },
        })
    }

    /// Bytes received but not yet decoded (a half frame, usually).
    pub fn buffered(&self) -> &[u8] {
        &self.buf
    }

    /// Forgets buffered bytes, e.g. before sending a new request.
    pub fn clear(&mut self) {
        self.buf.clear();
    }

    /// The codec.
    pub fn codec(&self) -> &C {
        &self.codec
    }

    /// The decode result at the front and how many bytes it spans.
    fn decode_front(&self) -> Option<(Decoded<C>, usize)> {
        if self.buf.is_empty() {
            return None;
        }
        match self.codec.decode(&self.buf) {
            Ok(None) => None,
            Ok(Some((frame, consumed))) => Some((Ok(frame), consumed.clamp(1, self.buf.len()))),
            Err(error) => {
                let drop = error.drop_len().clamp(1, self.buf.len());
                Some((Err(error), drop))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A toy codec: a frame is `<` + one byte + `>`.
    struct Angle;

    #[derive(Debug, PartialEq)]
    struct Bad(usize);

    impl Resync for Bad {
        fn drop_len(&self) -> usize {
            self.0
        }
    }

    impl Codec for Angle {
        type Frame = u8;
        type Error = Bad;
        fn decode(&self, buf: &[u8]) -> Result<Option<(u8, usize)>, Bad> {
            match buf {
                [b'<', b, b'>', ..] => Ok(Some((*b, 3))),
                [b'<'] | [b'<', _] => Ok(None),
                _ => Err(Bad(1)),
            }
        }
        fn encode(&self, frame: &u8, out: &mut Vec<u8>) {
            out.extend_from_slice(&[b'<', *frame, b'>']);
        }
    }

    fn frames(deframer: &mut Deframer<Angle>) -> Vec<Result<u8, Bad>> {
        std::iter::from_fn(|| deframer.next_frame()).collect()
    }

    #[test]
    fn deframer_waits_for_a_half_frame_and_completes_it() {
        let mut d = Deframer::new(Angle);
        d.push(b"<a");
        assert!(d.next_frame().is_none());
        assert_eq!(d.buffered(), b"<a");
        d.push(b">");
        assert_eq!(frames(&mut d), vec![Ok(b'a')]);
        assert!(d.buffered().is_empty());
    }

    #[test]
    fn deframer_drops_garbage_and_reports_each_drop() {
        let mut d = Deframer::new(Angle);
        d.push(b"xy<a><b>");
        assert_eq!(
            frames(&mut d),
            vec![Err(Bad(1)), Err(Bad(1)), Ok(b'a'), Ok(b'b')]
        );
    }

    #[test]
    fn deframer_chunks_carry_the_raw_bytes() {
        let mut d = Deframer::new(Angle);
        d.push(b"z<q>");
        assert_eq!(
            d.next_chunk(),
            Some(Chunk::Skipped {
                error: Bad(1),
                raw: b"z".to_vec()
            })
        );
        assert_eq!(
            d.next_chunk(),
            Some(Chunk::Frame {
                frame: b'q',
                raw: b"<q>".to_vec()
            })
        );
        assert_eq!(d.next_chunk(), None);
    }

    #[test]
    fn deframer_never_drops_more_than_it_holds() {
        struct Greedy;
        impl Codec for Greedy {
            type Frame = ();
            type Error = Bad;
            fn decode(&self, _: &[u8]) -> Result<Option<((), usize)>, Bad> {
                Err(Bad(usize::MAX))
            }
            fn encode(&self, _: &(), _: &mut Vec<u8>) {}
        }
        let mut d = Deframer::new(Greedy);
        d.push(b"abc");
        assert!(matches!(d.next_frame(), Some(Err(_))));
        assert!(d.next_frame().is_none());
    }
}
