//! A seeded byte mangler with the trouble of a bad serial line.
//!
//! Each chunk that crosses the line (what one read returned: usually one frame) may be
//! lost whole; otherwise each byte may have one bit flipped, be lost, be duplicated, or be
//! followed by an inserted random byte. A burst (a motor starting, a cable moved) garbles
//! a run of bytes. The same seed and the same traffic give the same trouble.

/// How often each kind of trouble happens.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseConfig {
    /// Probability that a byte has one random bit flipped.
    pub bit_flip: f64,
    /// Probability that a byte is lost.
    pub drop: f64,
    /// Probability that a random byte is inserted after a byte.
    pub insert: f64,
    /// Probability that a byte arrives twice.
    pub duplicate: f64,
    /// Probability that a whole chunk (a frame, usually) is lost.
    pub frame_drop: f64,
    /// Probability that a chunk is hit by a burst.
    pub burst: f64,
    /// Bytes a burst garbles (replaced by random bytes), at most.
    pub burst_len: usize,
}

impl NoiseConfig {
    /// A clean line.
    pub const CLEAN: Self = Self {
        bit_flip: 0.0,
        drop: 0.0,
        insert: 0.0,
        duplicate: 0.0,
        frame_drop: 0.0,
        burst: 0.0,
        burst_len: 0,
    };

    /// The noisy line of the field report this kit was written for: one bit in 0.2 % of
    /// the bytes, a byte lost or inserted in 0.03 %, plus rarer duplicates, lost frames
    /// and bursts.
    pub const FIELD: Self = Self {
        bit_flip: 0.002,
        drop: 0.0003,
        insert: 0.0003,
        duplicate: 0.0001,
        frame_drop: 0.001,
        burst: 0.0005,
        burst_len: 8,
    };

    /// Every rate multiplied by `factor` (capped at 1).
    pub fn scaled(self, factor: f64) -> Self {
        let s = |p: f64| (p * factor).clamp(0.0, 1.0);
        Self {
            bit_flip: s(self.bit_flip),
            drop: s(self.drop),
            insert: s(self.insert),
            duplicate: s(self.duplicate),
            frame_drop: s(self.frame_drop),
            burst: s(self.burst),
            burst_len: self.burst_len,
        }
    }
}

/// What the line did so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NoiseCounts {
    /// Chunks that crossed the line.
    pub chunks: u64,
    /// Bytes that crossed the line (before trouble).
    pub bytes: u64,
    /// Chunks that arrived changed or not at all.
    pub damaged_chunks: u64,
    /// Bits flipped.
    pub flipped: u64,
    /// Bytes lost (not counting lost chunks).
    pub dropped: u64,
    /// Bytes inserted.
    pub inserted: u64,
    /// Bytes duplicated.
    pub duplicated: u64,
    /// Whole chunks lost.
    pub frames_dropped: u64,
    /// Bursts.
    pub bursts: u64,
    /// Chunks lost while the line was out.
    pub lost_in_outage: u64,
}

impl NoiseCounts {
    /// The sum of two counts (both directions of a line, or several lines).
    pub fn plus(self, other: Self) -> Self {
        self.zip(other, |a, b| a + b)
    }

    /// What was counted since `earlier`.
    pub fn minus(self, earlier: Self) -> Self {
        self.zip(earlier, u64::saturating_sub)
    }

    fn zip(self, o: Self, f: impl Fn(u64, u64) -> u64) -> Self {
        Self {
            chunks: f(self.chunks, o.chunks),
            bytes: f(self.bytes, o.bytes),
            damaged_chunks: f(self.damaged_chunks, o.damaged_chunks),
            flipped: f(self.flipped, o.flipped),
            dropped: f(self.dropped, o.dropped),
            inserted: f(self.inserted, o.inserted),
            duplicated: f(self.duplicated, o.duplicated),
            frames_dropped: f(self.frames_dropped, o.frames_dropped),
            bursts: f(self.bursts, o.bursts),
            lost_in_outage: f(self.lost_in_outage, o.lost_in_outage),
        }
    }
}

/// One direction of a noisy line.
#[derive(Debug, Clone)]
pub struct Noise {
    config: NoiseConfig,
    rng: fastrand::Rng,
    counts: NoiseCounts,
}

impl Noise {
    /// A line with `config`'s trouble, reproducible from `seed`.
    pub fn new(config: NoiseConfig, seed: u64) -> Self {
        Self {
            config,
            rng: fastrand::Rng::with_seed(seed),
            counts: NoiseCounts::default(),
        }
    }

    /// Changes the trouble from now on (the counts and the random sequence go on).
    pub fn set_config(&mut self, config: NoiseConfig) {
        self.config = config;
    }

    /// What the line did so far.
    pub fn counts(&self) -> NoiseCounts {
        self.counts
    }

    /// Counts a chunk carried untouched (the noise switched off).
    pub fn pass(&mut self, chunk: &[u8]) {
        self.counts.chunks += 1;
        self.counts.bytes += chunk.len() as u64;
    }

    /// Counts a chunk lost whole because the line is out.
    pub fn lose(&mut self, chunk: &[u8]) {
        self.counts.chunks += 1;
        self.counts.bytes += chunk.len() as u64;
        self.counts.lost_in_outage += 1;
    }

    /// What arrives at the other end when `chunk` is sent.
    pub fn apply(&mut self, chunk: &[u8]) -> Vec<u8> {
        let c = self.config;
        self.counts.chunks += 1;
        self.counts.bytes += chunk.len() as u64;
        if self.hit(c.frame_drop) {
            self.counts.frames_dropped += 1;
            self.counts.damaged_chunks += 1;
            return Vec::new();
        }
        let mut out = Vec::with_capacity(chunk.len() + 2);
        for &byte in chunk {
            if self.hit(c.drop) {
                self.counts.dropped += 1;
                continue;
            }
            let mut byte = byte;
            if self.hit(c.bit_flip) {
                self.counts.flipped += 1;
                byte ^= 1 << self.rng.u8(0..8);
            }
            out.push(byte);
            if self.hit(c.duplicate) {
                self.counts.duplicated += 1;
                out.push(byte);
            }
            if self.hit(c.insert) {
                self.counts.inserted += 1;
                out.push(self.rng.u8(..));
            }
        }
        if c.burst_len > 0 && !out.is_empty() && self.hit(c.burst) {
            self.counts.bursts += 1;
            let start = self.rng.usize(..out.len());
            let len = self.rng.usize(1..=c.burst_len);
            for byte in out.iter_mut().skip(start).take(len) {
                *byte = self.rng.u8(..);
            }
        }
        if out != chunk {
            self.counts.damaged_chunks += 1;
        }
        out
    }

    fn hit(&mut self, p: f64) -> bool {
        p > 0.0 && self.rng.f64() < p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(config: NoiseConfig, seed: u64) -> (Vec<Vec<u8>>, NoiseCounts) {
        let mut noise = Noise::new(config, seed);
        let out = (0..2000u32)
            .map(|i| noise.apply(&i.to_be_bytes()))
            .collect();
        (out, noise.counts())
    }

    #[test]
    fn a_clean_line_changes_nothing() {
        let (out, counts) = run(NoiseConfig::CLEAN, 1);
        for (i, chunk) in out.iter().enumerate() {
            assert_eq!(chunk, &(i as u32).to_be_bytes());
        }
        assert_eq!(counts.damaged_chunks, 0);
        assert_eq!(counts.bytes, 8000);
    }

    #[test]
    fn the_same_seed_gives_the_same_trouble() {
        let noisy = NoiseConfig::FIELD.scaled(50.0);
        assert_eq!(run(noisy, 7), run(noisy, 7));
        assert_ne!(run(noisy, 7).0, run(noisy, 8).0);
    }

    #[test]
    fn a_noisy_line_shows_every_kind_of_trouble_and_counts_it() {
        let (out, counts) = run(NoiseConfig::FIELD.scaled(50.0), 3);
        assert!(counts.flipped > 0 && counts.dropped > 0 && counts.inserted > 0);
        assert!(counts.duplicated > 0 && counts.frames_dropped > 0 && counts.bursts > 0);
        let damaged = out
            .iter()
            .enumerate()
            .filter(|(i, c)| c.as_slice() != (*i as u32).to_be_bytes())
            .count() as u64;
        assert_eq!(damaged, counts.damaged_chunks);
    }
}
