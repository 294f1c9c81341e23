//! Files asammdf does not write but loggers do: an unsorted data group (every event as it
//! came, each record led by its record id) with the frames' bytes in a VLSD channel group, an
//! unfinalised file whose last DT block's length was never written, a file cut mid-record,
//! and blocks that lie. Built block by block here, as the standard lays them out.

use railfuse_mdf::bus::BusFrames;

/// An MDF file under construction: blocks appended, links patched.
struct Mdf(Vec<u8>);

impl Mdf {
    fn new(finalised: bool, flags: u16) -> Self {
        let mut id = vec![0u8; 64];
        id[0..8].copy_from_slice(if finalised { b"MDF     " } else { b"UnFinMF " });
        id[8..16].copy_from_slice(b"4.11    ");
        id[28..30].copy_from_slice(&411u16.to_le_bytes());
        id[60..62].copy_from_slice(&flags.to_le_bytes());
        Mdf(id)
    }
    fn block(&mut self, id: &[u8; 4], links: &[u64], data: &[u8]) -> u64 {
        let at = self.0.len() as u64;
        let len = 24 + 8 * links.len() + data.len();
        self.0.extend_from_slice(id);
        self.0.extend_from_slice(&[0; 4]);
        self.0.extend_from_slice(&(len as u64).to_le_bytes());
        self.0
            .extend_from_slice(&(links.len() as u64).to_le_bytes());
        for l in links {
            self.0.extend_from_slice(&l.to_le_bytes());
        }
        self.0.extend_from_slice(data);
        while self.0.len() % 8 != 0 {
            self.0.push(0);
        }
        at
    }
    fn link(&mut self, block: u64, i: usize, to: u64) {
        let at = block as usize + 24 + 8 * i;
        self.0[at..at + 8].copy_from_slice(&to.to_le_bytes());
    }
    fn text(&mut self, t: &str) -> u64 {
        let mut d = t.as_bytes().to_vec();
        d.push(0);
        self.block(b"##TX", &[], &d)
    }
    /// A channel: type, data type, bit offset, byte offset, bits; its name, conversion, data.
    fn channel(
        &mut self,
        name: &str,
        kind: u8,
        dtype: u8,
        bit: u8,
        byte: u32,
        bits: u32,
        cc: u64,
    ) -> u64 {
        let name = self.text(name);
        let mut d = vec![kind, 0, dtype, bit];
        d.extend_from_slice(&byte.to_le_bytes());
        d.extend_from_slice(&bits.to_le_bytes());
        d.extend_from_slice(&[0; 12 + 48]);
        self.block(b"##CN", &[0, 0, name, 0, cc, 0, 0, 0], &d)
    }
    fn group(&mut self, name: &str, record_id: u64, flags: u16, bytes: u32) -> u64 {
        let name = self.text(name);
        let mut d = record_id.to_le_bytes().to_vec();
        d.extend_from_slice(&0u64.to_le_bytes());
        d.extend_from_slice(&flags.to_le_bytes());
        d.extend_from_slice(&[0; 6]);
        d.extend_from_slice(&bytes.to_le_bytes());
        d.extend_from_slice(&0u32.to_le_bytes());
        self.block(b"##CG", &[0, 0, name, 0, 0, 0], &d)
    }
}

const START_NS: u64 = 1_627_274_454_000_000_000;

/// An unsorted bus log of `n` frames, each VLSD record before its frame's record; the DT
/// block's declared length is `declared(actual)`.
fn unsorted(n: u64, finalised: bool, flags: u16, declared: impl Fn(u64) -> u64) -> Vec<u8> {
    let mut m = Mdf::new(finalised, flags);
    let mut hd = START_NS.to_le_bytes().to_vec();
    hd.extend_from_slice(&[0; 24]);
    let hd_at = m.block(b"##HD", &[0; 6], &hd);
    let dg = m.block(b"##DG", &[0, 0, 0, 0], &[1, 0, 0, 0, 0, 0, 0, 0]);
    m.link(hd_at, 0, dg);
    let frames = m.group("CAN_DataFrame", 1, 2 | 4, 21);
    let vlsd = m.group("", 2, 1, 0);
    m.link(dg, 1, frames);
    m.link(frames, 0, vlsd);
    let mut cc = vec![1u8, 0, 0, 0, 0, 0, 2, 0];
    cc.extend_from_slice(&[0; 16]);
    cc.extend_from_slice(&0f64.to_le_bytes());
    cc.extend_from_slice(&1e-9f64.to_le_bytes());
    let ns = m.block(b"##CC", &[0, 0, 0, 0], &cc);
    let time = m.channel("Timestamp", 2, 0, 0, 0, 64, ns);
    let parent = m.channel("CAN_DataFrame", 0, 10, 0, 8, 13 * 8, 0);
    let ide = m.channel("CAN_DataFrame.IDE", 0, 0, 0, 8, 1, 0);
    let bus = m.channel("CAN_DataFrame.BusChannel", 0, 0, 1, 8, 2, 0);
    let id = m.channel("CAN_DataFrame.ID", 0, 0, 3, 8, 29, 0);
    let len = m.channel("CAN_DataFrame.DataLength", 0, 0, 0, 12, 8, 0);
    let bytes = m.channel("CAN_DataFrame.DataBytes", 1, 10, 0, 13, 64, 0);
    m.link(bytes, 5, vlsd);
    m.link(frames, 1, time);
    m.link(time, 0, parent);
    m.link(parent, 1, ide);
    for (a, b) in [(ide, bus), (bus, id), (id, len), (len, bytes)] {
        m.link(a, 0, b);
    }
    let mut records = Vec::new();
    let mut offset = 0u64;
    for k in 0..n {
        let data: Vec<u8> = (0..(k % 9) as u8).map(|b| b * 17 + k as u8).collect();
        records.push(2u8);
        records.extend_from_slice(&(data.len() as u32).to_le_bytes());
        records.extend_from_slice(&data);
        records.push(1u8);
        records.extend_from_slice(&(k * 10_000_000).to_le_bytes());
        let extended = k % 2 == 1;
        let word = u32::from(extended) | (1 + (k % 2) as u32) << 1 | (0x100 + k as u32) << 3;
        records.extend_from_slice(&word.to_le_bytes());
        records.push(data.len() as u8);
        records.extend_from_slice(&offset.to_le_bytes());
        offset += 4 + data.len() as u64;
    }
    let dt = m.0.len() as u64;
    m.0.extend_from_slice(b"##DT\0\0\0\0");
    m.0.extend_from_slice(&(24 + declared(records.len() as u64)).to_le_bytes());
    m.0.extend_from_slice(&0u64.to_le_bytes());
    m.0.extend_from_slice(&records);
    m.link(dg, 2, dt);
    m.0
}

fn read(
    bytes: &[u8],
) -> (
    Vec<railfuse_can::frame::Frame>,
    railfuse_mdf::bus::BusReport,
) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.mf4");
    std::fs::write(&p, bytes).unwrap();
    let mut f = BusFrames::open(&p).unwrap();
    let frames: Vec<_> = f.by_ref().collect();
    (frames, f.report.clone())
}

#[test]
fn an_unsorted_group_with_vlsd_records_gives_every_frame() {
    let (frames, report) = read(&unsorted(50, true, 0, |n| n));
    assert_eq!(frames.len(), 50);
    assert_eq!(report.damage, None);
    let f = &frames[7];
    assert_eq!(f.stamp_ns, START_NS + 70_000_000);
    assert_eq!((f.bus.as_str(), f.id, f.extended), ("CAN2", 0x107, true));
    assert_eq!(f.data, (0..7u8).map(|b| b * 17 + 7).collect::<Vec<_>>());
    assert_eq!((frames[0].bus.as_str(), frames[0].data.len()), ("CAN1", 0));
}

#[test]
fn an_unfinalised_file_reads_to_the_end_of_its_data() {
    // The logger never wrote the DT block's length (flag bit 1): it runs to the file's end.
    let (frames, report) = read(&unsorted(40, false, 2, |_| 0));
    assert_eq!(frames.len(), 40);
    assert!(!report.finalised);
}

#[test]
fn a_file_cut_mid_record_keeps_the_frames_before_the_cut() {
    let whole = unsorted(40, true, 0, |n| n);
    let (frames, report) = read(&whole[..whole.len() - 10]);
    assert_eq!(frames.len(), 39);
    let d = report.damage.unwrap();
    assert!(
        d.contains("past the file's end") || d.contains("cut off"),
        "{d}"
    );
}

#[test]
fn a_record_id_no_group_has_ends_the_reading_there() {
    let mut bytes = unsorted(10, true, 0, |n| n);
    // The fifth record's id (after four VLSD and four frame records of known sizes).
    let dt = bytes.windows(4).position(|w| w == b"##DT").unwrap() + 24;
    let mut at = dt;
    for k in 0..4usize {
        at += 1 + 4 + k % 9 + 1 + 21;
    }
    bytes[at] = 9;
    let (frames, report) = read(&bytes);
    assert_eq!(frames.len(), 4);
    assert!(report.damage.unwrap().contains("record id 9"));
}

#[test]
fn lying_sizes_are_refused_before_anything_is_allocated() {
    let mut bytes = unsorted(3, true, 0, |n| n);
    // The DG claims ten thousand million links.
    let dg = bytes.windows(4).position(|w| w == b"##DG").unwrap();
    bytes[dg + 16..dg + 24].copy_from_slice(&10_000_000_000u64.to_le_bytes());
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.mf4");
    std::fs::write(&p, &bytes).unwrap();
    let e = BusFrames::open(&p).err().unwrap().to_string();
    assert!(e.contains("claims 10000000000 links"), "{e}");
}
