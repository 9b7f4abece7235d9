"""Offline datasets: collection, storage, subsets and mixtures, Minari and the authors' format.

collect(policy, task, transitions, seed=, n_envs=, labels=) -> Dataset   # gcdt.data.collect
Dataset.save(path) / load_dataset(path)                        # one .npz, atomic
subset(dataset, size, seed) / mix(expert, random, ratio, size, seed)   # RQ4 / RQ5
export_minari(dataset, id) / import_minari(id)                 # gcdt.data.minari_io
import_authors(pickle_path, trust_pickle=True) / export_authors(dataset, path)  # authors.py
"""

from gcdt.data.authors import export_authors, import_authors
from gcdt.data.collect import LABELS, collect, from_episodes
from gcdt.data.dataset import SCHEMA_VERSION, Dataset, load_dataset
from gcdt.data.minari_io import export_minari, import_minari
from gcdt.data.mixing import concatenate, mix, subset

__all__ = [
    "LABELS",
    "SCHEMA_VERSION",
    "Dataset",
    "collect",
    "concatenate",
    "export_authors",
    "export_minari",
    "from_episodes",
    "import_authors",
    "import_minari",
    "load_dataset",
    "mix",
    "subset",
]
