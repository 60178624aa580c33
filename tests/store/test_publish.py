"""Store.publish: one manifest and its ref under one lock; reuse of an identical result."""

from __future__ import annotations

from morfic_cli.store import Store


def test_publish_stores_the_manifest_and_advances_the_ref(tmp_path):
    store = Store(tmp_path / "s")
    first = store.publish("table", "tables/t", config={"a": 1}, files={"t.csv": b"x\n"}, meta={"n": 1})
    assert (first.ref, first.version, first.reused) == ("tables/t", 1, False)
    manifest = store.read_manifest("tables/t")
    assert manifest.id == first.id and manifest.config == {"a": 1} and manifest.meta == {"n": 1}
    assert store.read_file(first.id, "t.csv") == b"x\n"
    second = store.publish("table", "tables/t", config={"a": 2}, files={"t.csv": b"y\n"})
    assert second.version == 2 and second.id != first.id


def test_reuse_takes_the_same_result_without_building_its_files(tmp_path):
    store = Store(tmp_path / "s")
    built = []

    def files():
        built.append(1)
        return {"t.csv": b"x\n"}

    first = store.publish("table", "tables/t", config={"a": 1}, files=files, reuse=True)
    again = store.publish("table", "tables/u", config={"a": 1}, files=files, reuse=True)
    assert built == [1]  # built once, for the first
    assert again.reused and again.id == first.id and again.version == 1
    other = store.publish("table", "tables/u", config={"a": 3}, files=files, reuse=True)
    assert not other.reused and built == [1, 1] and other.version == 2


def test_publish_without_a_ref_stores_only_the_manifest(tmp_path):
    store = Store(tmp_path / "s")
    pub = store.publish("table", config={"a": 1})
    assert pub.ref is None and pub.version is None
    assert store.list_refs() == [] and store.read_manifest(pub.id).config == {"a": 1}
