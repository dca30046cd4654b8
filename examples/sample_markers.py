"""Write a sample marker record for `spotsim plot --markers`: synthetic, not a measurement.

    python examples/sample_markers.py [--out examples/markers_sample.csv]

Runs config/spot_testbed_3mm.yaml without writing its results, samples its bodies' displacements
at the SPOT cameras' 90 Hz (as `markers.csv`), adds a motion-capture system's noise (independent
Gaussian, NOISE_MM on positions and NOISE_DEG on yaw, seeded) and writes the record in the form a
measured one takes (docs/usage.md, "The SPOT testbed and marker records"). Compared with the run
(`spotsim plot results/spot_testbed_3mm --markers examples/markers_sample.csv`), each column's RMS
difference is that noise: the file shows the form and the comparison, it holds no testbed data.
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np

import spotsim
from spotsim import measures

ROOT = Path(__file__).resolve().parents[1]
#: [assumption] The noise of a marker's position and yaw in an optical motion-capture record of a
#: table-sized volume: 0.1 mm and 0.05 deg (one standard deviation).
NOISE_MM, NOISE_DEG = 0.1, 0.05
SEED = 0


def sample_record(result) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The run's camera record (its `markers.csv`) with the noise added."""
    with tempfile.TemporaryDirectory() as tmp:
        out = spotsim.write_results(result, tmp, figures=False)
        times, columns = measures.read_markers(out / "markers.csv")
    rng = np.random.default_rng(SEED)
    noisy = {name: values + rng.normal(0.0, NOISE_DEG if name.endswith("_deg") else NOISE_MM, values.shape)
             for name, values in columns.items()}
    return times, noisy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "examples" / "markers_sample.csv")
    args = parser.parse_args()
    result = spotsim.simulate(spotsim.load_scenario("spot_testbed_3mm"))
    times, columns = sample_record(result)
    args.out.write_text(measures.markers_csv(times, columns))
    print(f"{args.out}: {len(times)} rows of {len(columns)} columns at {measures.CAMERA_HZ:g} Hz, "
          f"{result.scenario.name}'s record with {NOISE_MM} mm and {NOISE_DEG} deg noise (synthetic)")


if __name__ == "__main__":
    main()
