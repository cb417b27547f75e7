"""What a bench (and a fit) can do at all: the bounds on numbers the command line and a schedule may ask for.

One home for these numbers. The command line refuses anything beyond them at parse time (benchlab.cliargs),
`protocols.limits.check_schedule` refuses a schedule planned longer than a run may last. They are not the
bench's set-point limits (protocols.limits.BenchLimits, per bench): they stop a typo such as
`--duration 1e12` or `(@1:99999999)` from allocating memory until the machine gives up.
"""

from __future__ import annotations

#: Longest run: a week unattended. The run file is allocated for the planned duration when the run starts
#: (about 1.6 GB per day with the simulated bench's streams and the 10 ms grid), so this also bounds the file.
MAX_RUN_DURATION_S = 7 * 24 * 3600.0
#: Fastest pace `benchlab run --realtime` asks of the simulated bench: beyond it a tick's own work (ms) sets the pace.
MAX_REALTIME_FACTOR = 1000.0
#: Slowest pace: a hundredth of real time (slow motion for watching a launch); 1e-9 paced a 60 s run over 1900 years.
MIN_REALTIME_FACTOR = 0.01
#: Most cycles one run may plan: 10 000 Table 1 cycles (40-130 s each) are 5-15 days, so a run this long is
#: refused by MAX_RUN_DURATION_S first for all but the shortest cycles.
MAX_CYCLES = 10_000
#: Channels one scan of the PT1000 scanner can hold: three slots of a 20-channel multiplexer
#: (34970A/34972A/DAQ970A with 34901A/DAQM901A cards).
MAX_SCAN_CHANNELS = 60
#: Longest wait for a device to answer: a longer time-out is a typo, not a slow device.
MAX_TIMEOUT_S = 600.0
#: Most readings `benchlab probe` takes (scans or frames): a probe looks at a device, it does not log.
MAX_PROBE_READINGS = 10_000
#: Most starting points of a grey-box fit (each is a full least-squares fit).
MAX_FIT_STARTS = 1_000
#: Longest fitting step: an hour (a thermal model of anything sampled faster is still fitted at this step).
MAX_FIT_STEP_S = 3600.0
#: Most Monte Carlo paths of the remaining-life estimate: each path holds one resampled load profile.
MAX_WEAR_PATHS = 100_000
#: Longest wear horizon in engagements: a passenger-car clutch sees about a million in its life.
MAX_WEAR_HORIZON = 1_000_000_000
#: Bit rates of a classic CAN bus, bit/s: 5 kbit/s, the lowest common controllers set, to 1 Mbit/s, the
#: standard's highest (the bench's DBC is classic CAN).
MIN_CAN_BITRATE = 5_000
MAX_CAN_BITRATE = 1_000_000
#: Longest residual sampling period of the cool-down analysis: one sample an hour still shows a trend.
MAX_SAMPLE_PERIOD_S = 3600.0
#: Coarsest /aligned grid of a run file `benchlab run` continues (`--resume`): a bench samples at 10 ms, so a
#: stored step of a minute is already a tampered or foreign file (and rows × dt sets the resumed run's clock).
MAX_GRID_STEP_S = 60.0
#: Most times one run may be resumed: each resume is a crash or a Ctrl-C and a CAN log of its own.
MAX_RESUMES = 10_000
#: Most columns of a CSV `benchlab import` reads: a run file holds a few dozen channels; the bound is checked on
#: the header line, before any row is parsed (a 100 000-column file used to take 104 s to be refused).
MAX_CSV_COLUMNS = 1_000
#: Most channels a mapping file may map (`benchlab import --mapping`): as many as a CSV may have columns; each is a
#: source channel read, resampled and written on its own (10 000 entries took over a minute before a word was said).
MAX_MAPPED_CHANNELS = MAX_CSV_COLUMNS
#: Largest time stamp of a run file's grid, s: run time, or Unix time of an imported log (1e10 s is the year 2286).
#: Beyond it float64 no longer resolves a 10 ms grid, and the uniform-grid check would pass anything.
MAX_TIME_STAMP_S = 1e10
#: Most worker processes of a local batch cluster: each takes a core and a run in memory; more is a typo.
MAX_LOCAL_WORKERS = 256
#: Most grid rows `benchlab import` puts an MDF file's channels on: a week's run on the bench's 10 ms grid (a
#: finer --dt over a long recording is a typo that would allocate memory until the machine gives up).
MAX_IMPORT_ROWS = int(MAX_RUN_DURATION_S / 0.01)
#: The physical range of each BENCH.toml number that feeds a loop or a division: beyond it is a typo, not a bench
#: (`gear_ratio = 1e-300` made the launch estimate of `run --dry-run` loop without end). A gear ratio between the
#: input shaft and the load machine of 1:10 to 100:1; a load inertia from a light rotor to a heavy dynamometer; serial
#: lines from 300 baud to 12 Mbaud (USB adapters); device periods and the run's ticks from 1 ms (no device or loop
#: of the bench is faster) to what still makes a measurement; the grid at most 0.1 s and a tick at most 0.5 s (the
#: interlocks are polled twice a second at least, a launch's slip every 0.1 s), the run file flushed at least once a
#: second (a crash loses at most 1 s, docs/runfile.md).
BENCH_NUMBER_RANGES = {
    "drivetrain.gear_ratio": (0.1, 100.0),
    "drivetrain.load_inertia_kgm2": (1e-3, 1e5),
    "instrument.baudrate": (300, 12_000_000),
    "node.baudrate": (300, 12_000_000),
    "instrument.timeout_s": (1e-3, MAX_TIMEOUT_S),
    "instrument.period_s": (1e-3, 3600.0),
    "node.period_s": (1e-3, 60.0),
    "acquisition.dt": (1e-3, 0.1),
    "acquisition.tick_s": (1e-3, 0.5),
    "acquisition.fast_tick_s": (1e-3, 0.1),
    "acquisition.flush_every_s": (1e-3, 1.0),
}
#: Most bytes a compressed input (an MDF file's ##DZ blocks, a BLF log's containers) may declare it inflates to, as
#: a multiple of the file's own size: measurement data compress 2-10 times (the bench's own MF4 export: see
#: docs/runfile.md), and a file claiming more is a compression bomb (1.3 MB declaring a TB crashed the MDF reader).
MAX_INFLATION = 50
#: The same for a BLF log, whose every 48-byte CAN object python-can makes a Python message of (some 10 us each):
#: 20 times 10 MB is about 4 M frames, under a minute and under 1 GB (the bench's own BLF log declares 7 times).
MAX_BLF_INFLATION = 20
#: What any compressed input may inflate to however small it is: a short log's one container or a few MDF blocks of
#: constant values compress far more than a long recording does.
INFLATION_FLOOR_BYTES = 16 << 20
#: Most bytes any one input may inflate to, whatever its size: a week of 100 channels at 100 Hz as float64 is 48 GB,
#: more than a bench PC holds in memory; 8 GiB is a long run's worth.
MAX_INFLATED_BYTES = 8 << 30
#: Memory a foreign file's reader (asammdf, python-can) runs within, in a child process, beyond what the command
#: already holds: this floor plus READER_MEMORY_PER_BYTE for every byte of the file and of what it declares it
#: inflates to. A reader asking for more is stopped (a file that inflates beyond what it declares).
READER_MEMORY_FLOOR = 512 << 20
READER_MEMORY_PER_BYTE = 4
#: CPU seconds a foreign file's reader gets: this floor plus READER_CPU_S_PER_MB per MB of the file and of what it
#: declares it inflates to. The bench's own BLF log of a Table 1 run (18 MB, 129 MB of objects, 2.8 M frames)
#: imports in 26 s, its MF4 export (13 MB, 140 MB inflated) in 26 s: 1 s per MB leaves five times that.
READER_CPU_FLOOR_S = 30.0
READER_CPU_S_PER_MB = 1.0
