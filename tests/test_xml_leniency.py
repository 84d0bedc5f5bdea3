"""XML as BehaviorTree.CPP reads it: every form tinyxml2 tolerates that real trees use, read
with the values BT.CPP gives them (checked by running each in BT.CPP through behaviortreepy
when it is installed), with the lines of errors right, and nothing unsafe let in."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from btlog.tree.loader import TreeError, load_tree_text
from tests.cli_support import assert_bad_input, btlog
from tests.oracle.runner import have_behaviortreepy, run_oracle


def document(body: str, head: str = "", tail: str = "") -> str:
    """A v4 document whose main tree ``M`` is ``body``; ``head`` before ``<root>``."""
    return (
        f'{head}<root BTCPP_format="4" main_tree_to_execute="M">\n'
        f'<BehaviorTree ID="M">\n{body}\n</BehaviorTree>\n</root>{tail}'
    )


#: (id, document, {node name: {port or attribute: value}}) — each a form tinyxml2 accepts.
FORMS = [
    (
        "raw && < > in a script",  # BT.CPP's scripting tutorial
        document(
            '<Sequence name="s"><Script code="A:=3; B:=1; C:=\'y\'"/>'
            '<Precondition if="A>-B && C != \'x\' && B<A" else="FAILURE">'
            '<AlwaysSuccess name="guarded"/></Precondition></Sequence>'
        ),
        {"Precondition": {"if": "A>-B && C != 'x' && B<A"}},
    ),
    (
        "dashes in comments",
        document('<!------->\n<!-- a -- b --- c -->\n<AlwaysSuccess name="x"/>'),
        {"x": {}},
    ),
    (
        "an & that starts no entity",
        document('<AlwaysSuccess name="R&D &foo; &amp &amp;"/>'),
        {"R&D &foo; &amp &": {}},
    ),
    (
        "character references",
        document('<AlwaysSuccess name="&#65;&#x42;&#X43;&#xZZ;&#12a;&#0;cut"/>'),
        {"AB&#X43;&#xZZ;&#12a;": {}},
    ),
    (
        "a declaration after blank lines",
        document('<AlwaysSuccess name="x"/>', head='\n\n  <?xml version="1.0"?>\n'),
        {"x": {}},
    ),
    (
        "attributes without spaces between them",
        document('<AlwaysSuccess name="x"_skipIf="false"/>'),
        {"x": {"_skipIf": "false"}},
    ),
    (
        "space after <",
        document('< Sequence name="s">< AlwaysSuccess name="x"/></Sequence>'),
        {"s": {}, "x": {}},
    ),
    (
        "tabs and quotes kept in attribute values",
        document("<AlwaysSuccess name='a\tb \"q\" <>'/>"),
        {'a\tb "q" <>': {}},
    ),
    (
        "content after the root element",
        document('<AlwaysSuccess name="x"/>', tail="\n<!-- c --><extra a='1'/>text &<more/>"),
        {"x": {}},
    ),
    (
        "anything after a stray closing tag",
        document('<AlwaysSuccess name="x"/>', tail="</root></root> not < xml"),
        {"x": {}},
    ),
    (
        "CR LF line ends",
        document('<Sequence name="s">\r\n<AlwaysSuccess name="x"/>\r\n</Sequence>').replace(
            "\n", "\r\n"
        ),
        {"s": {}, "x": {}},
    ),
]


def _read(xml: str) -> dict[str, dict[str, str]]:
    tree = load_tree_text(xml)
    return {
        node.name: {**{k: p.value for k, p in node.ports.items()}, **node.attributes}
        for node in tree
    }


@pytest.mark.parametrize(("form", "xml", "expected"), FORMS, ids=[f[0] for f in FORMS])
def test_tolerated_form_is_read_as_btcpp_reads_it(
    form: str, xml: str, expected: dict[str, dict[str, str]]
) -> None:
    read = _read(xml)
    for name, values in expected.items():
        assert name in read, (form, sorted(read))
        for key, value in values.items():
            assert read[name][key] == value, (form, name, key)


@pytest.fixture(scope="module")
def btcpp_runs() -> list[dict | None]:
    if not have_behaviortreepy():
        pytest.skip("behaviortreepy missing")
    cases = [{"xml": xml, "max_ticks": 3} for _, xml, _ in FORMS]
    with ThreadPoolExecutor(max_workers=2) as pool:
        return list(pool.map(run_oracle, cases))


@pytest.mark.parametrize("index", range(len(FORMS)), ids=[f[0] for f in FORMS])
def test_btcpp_accepts_the_form_and_names_its_nodes_alike(btcpp_runs, index: int) -> None:
    """BT.CPP runs each document, and the names it logs are the names btlog read."""
    form, xml, _ = FORMS[index]
    result = btcpp_runs[index]
    assert result is not None and result["error"] is None, (form, result)
    logged = {name for _, name, _, _ in result["transitions"]}
    assert logged and logged <= set(_read(xml)), (form, logged)


def test_the_scripting_tutorials_precondition_runs(tmp_path: Path) -> None:
    """A raw ``>`` and ``&&`` in a Precondition's script runs, from the command line."""
    path = tmp_path / "tutorial.xml"
    path.write_text(FORMS[0][1])
    result = btlog("run", path, "-o", tmp_path / "t.mcap")
    assert result.returncode == 0, result.stderr
    shown = btlog("timeline", tmp_path / "t.mcap", "--node", "guarded")
    assert "SUCCESS" in shown.stdout, shown.stdout


@pytest.mark.parametrize(
    ("xml", "line", "problem"),
    [
        # a lenient form first, then an error: the error's line is still right
        (
            document(
                '<Sequence name="s">\n<!-- a -- b\n-- c -->\n<Frobnicate><AlwaysSuccess/>'
                "</Frobnicate></Sequence>"
            ),
            6,
            "unknown node type 'Frobnicate'",
        ),
        (
            document(
                '<Sequence name="s" _skipIf="a\n&&\nb">\n<Frobnicate><AlwaysSuccess/>'
                "</Frobnicate></Sequence>"
            ),
            6,
            "unknown node type 'Frobnicate'",
        ),
        (
            document(
                '<Sequence name="s">\r\n\r\n<Frobnicate><AlwaysSuccess/></Frobnicate></Sequence>'
            ),
            5,
            "unknown node type 'Frobnicate'",
        ),
        (document('<Sequence name="s">\n<AlwaysSuccess/>\n</Sequenc>'), 5, "malformed XML"),
        (document('<Sequence name="s">\n<AlwaysSuccess name="a" name="b"/>'), 4, "twice"),
        (document('<Sequence name="s">\n<AlwaysSuccess name=a/>'), 4, "malformed attribute"),
        (document('<Sequence name="s">\n<!-- never closed'), 4, "comment is never closed"),
        (
            document('<Sequence name="s">\n<AlwaysSuccess/>'),
            5,
            "</BehaviorTree> closes <Sequence> opened at line 3",
        ),
        ('<root>\n<BehaviorTree ID="M">\n<AlwaysSuccess/>', 2, "<BehaviorTree> is never closed"),
        (document("<AlwaysSuccess/>", tail="\ntext"), 6, "text after the last tag"),
        (document('<Sequence name="s">\n a < 5 </Sequence>'), 4, "not followed by an element"),
        (
            document("<AlwaysSuccess/>", head='<!-- c -->\n<?xml version="1.0"?>\n'),
            2,
            "declaration",
        ),
        ("   \n\n", 1, "no element"),
    ],
)
def test_errors_name_the_right_line(xml: str, line: int, problem: str) -> None:
    with pytest.raises(TreeError) as caught:
        load_tree_text(xml, file="tree.xml")
    assert (caught.value.file, caught.value.line) == ("tree.xml", line), str(caught.value)
    assert problem in str(caught.value)
    assert "\n" not in str(caught.value)


def test_no_entity_is_declared_or_fetched(tmp_path: Path) -> None:
    """A DOCTYPE is refused wherever it is, an undeclared entity stays text, and an
    external one is never read: its file's content appears nowhere."""
    secret = tmp_path / "secret.txt"
    secret.write_text("TOPSECRET")
    for head in (
        f'<!DOCTYPE root [<!ENTITY x SYSTEM "file://{secret}">]>\n',
        f'<!doctype root SYSTEM "file://{secret}">\n',
    ):
        with pytest.raises(TreeError, match="DOCTYPE"):
            load_tree_text(document('<AlwaysSuccess name="&x;"/>', head=head))
    assert _read(document('<AlwaysSuccess name="&x;"/>')) == {"&x;": {}}
    path = tmp_path / "ent.xml"
    path.write_text(document('<AlwaysSuccess name="&x;"/>', head=f'<!ENTITY x SYSTEM "{secret}">'))
    result = btlog("validate", path)
    assert_bad_input(result, "ent.xml:1", "DOCTYPE")
    assert "TOPSECRET" not in result.stdout + result.stderr


def test_nesting_is_bounded_without_recursion() -> None:
    """100,000 nested elements are refused at the first level past the bound, quickly and
    without a RecursionError."""
    deep = "<Inverter>\n" * 100_000
    with pytest.raises(TreeError) as caught:
        load_tree_text(document(deep))
    assert "nested more than 256" in str(caught.value)
    assert caught.value.line == 3 + 254


def test_bytes_that_are_not_utf8_and_a_nul_byte() -> None:
    """tinyxml2 reads bytes: a Latin-1 comment is no error, and the document ends at NUL."""
    latin = document('<!-- caf\xe9 --><AlwaysSuccess name="x"/>').encode("latin-1")
    assert _read_bytes(latin) == {"x"}
    with pytest.raises(TreeError, match="never closed"):
        load_tree_text(document('<AlwaysSuccess name="x"/>').encode().replace(b"</B", b"\0</B"))


def _read_bytes(data: bytes) -> set[str]:
    return {node.name for node in load_tree_text(data)}


# -- properties: agreement with a conforming parser, and no crash on any input ----------
_NAMES = st.from_regex(r"[A-Za-z_][A-Za-z0-9_.-]{0,8}", fullmatch=True)
_TEXT = st.text(
    st.characters(blacklist_categories=("Cs", "Cc", "Cn", "Co"), blacklist_characters="<>&\"'"),
    max_size=12,
)


@st.composite
def _documents(draw: st.DrawFn, depth: int = 0) -> str:
    """A well-formed element: attributes without tabs or newlines (which XML would turn
    into spaces and tinyxml2 keeps), children, comments, text."""
    tag = draw(_NAMES)
    names = draw(st.lists(_NAMES, max_size=4, unique=True))
    attributes = "".join(f' {n}="{draw(_TEXT)}"' for n in names)
    if depth >= 3 or not draw(st.booleans()):
        return f"<{tag}{attributes}/>"
    parts = []
    for _ in range(draw(st.integers(0, 3))):
        kind = draw(st.sampled_from(["element", "comment", "text", "newline"]))
        if kind == "element":
            parts.append(draw(_documents(depth + 1)))
        elif kind == "comment":
            parts.append(f"<!-- {draw(_TEXT)} -->")
        elif kind == "text":
            parts.append(draw(_TEXT))
        else:
            parts.append("\n")
    return f"<{tag}{attributes}>{''.join(parts)}</{tag}>"


def _shape(element: Any) -> tuple:
    """Tag, attributes, line and children of an lxml or a btlog element."""
    children = [c for c in element if isinstance(c.tag, str)]
    return (element.tag, dict(element.attrib), element.sourceline, [_shape(c) for c in children])


@settings(max_examples=200, deadline=None, derandomize=True)
@given(_documents())
def test_well_formed_xml_reads_as_a_conforming_parser_reads_it(document: str) -> None:
    """Where XML and tinyxml2 agree (well-formed documents), btlog's reader gives lxml's
    elements, attributes and lines."""
    from lxml import etree

    from btlog.tree.xml_syntax import parse

    expected = etree.fromstring(document.encode(), etree.XMLParser(resolve_entities=False))
    assert _shape(parse(document.encode(), 256, 1000)) == _shape(expected)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.binary(max_size=300) | st.text(alphabet="<>/!?-[]&;=\"' ab\n\t\r#x", max_size=120))
def test_any_input_is_read_or_refused_in_one_line(data: bytes | str) -> None:
    from btlog.tree.xml_syntax import XmlSyntaxError, parse

    try:
        parse(data if isinstance(data, bytes) else data.encode(), 256, 1000)
    except XmlSyntaxError as error:
        assert error.line >= 1 and "\n" not in error.problem
