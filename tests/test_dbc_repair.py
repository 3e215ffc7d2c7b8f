"""DBC text repairs (canest/codec/dbc_repair.py): each repair on the line cantools refuses, the loader's warning
naming file, line and repair, and every DBC opendbc ships loading."""
import logging
from pathlib import Path

import pytest

from canest.codec import dbc_repair
from canest.codec.dbc import load_database, tolerated_problems
from canest.errors import DbcError

HEADER = 'VERSION ""\nNS_ :\nBS_:\nBU_: XXX\n'
MESSAGE = 'BO_ 304 GAS: 8 XXX\n SG_ PEDAL : 7|8@0+ (1,0) [0|255] "" XXX\n SG_ COUNTER : 15|4@0+ (1,0) [0|15] "" XXX\n'


def repaired(function, text, *args):
    lines = text.split("\n")
    repairs = function(lines, *args)
    return "\n".join(lines), repairs


@pytest.mark.parametrize("function, source, expected, lines", [
    (dbc_repair.signal_comment_without_signal, 'CM_ SG_ 304 "platform-agnostic";\nCM_ SG_ 304 PEDAL "ok";',
     'CM_ BO_ 304 "platform-agnostic";\nCM_ SG_ 304 PEDAL "ok";', [1]),
    (dbc_repair.comment_without_object, 'CM_ 145 "pedal";\nCM_ BO_ 145 "x";',
     'CM_ BO_ 145 "pedal";\nCM_ BO_ 145 "x";', [1]),
    (dbc_repair.missing_semicolon,
     'CM_ "Front target"\nVAL_ 320 OFF 2 "PERMANENT" 1 "TEMP"\nCM_ "multi\nline";\nVAL_ 3 A 1 "x" ;',
     'CM_ "Front target";\nVAL_ 320 OFF 2 "PERMANENT" 1 "TEMP";\nCM_ "multi\nline";\nVAL_ 3 A 1 "x" ;', [1, 2]),
    (dbc_repair.bare_decimal_point, ' SG_ TORQ : 4|13@0+ (.25,-.5) [-500|.75] "NM" XXX\nCM_ BO_ 1 "costs .25";',
     ' SG_ TORQ : 4|13@0+ (0.25,-0.5) [-500|0.75] "NM" XXX\nCM_ BO_ 1 "costs .25";', [1]),
])
def test_a_line_repair_changes_only_the_lines_cantools_refuses(function, source, expected, lines):
    text, repairs = repaired(function, source)
    assert text == expected and [repair.line for repair in repairs] == lines


def test_a_name_starting_with_a_digit_is_renamed_everywhere_it_is_used():
    text, repairs = repaired(dbc_repair.name_starting_with_digit,
                             'BO_ 1275 2017_5: 8 XXX\n SG_ 0_COUNTER : 35|4@0+ (1e-05,0) [0|15] "" XXX\n'
                             'VAL_ 1275 0_COUNTER 1 "one" ;')
    assert text == ('BO_ 1275 _2017_5: 8 XXX\n SG_ _0_COUNTER : 35|4@0+ (1e-05,0) [0|15] "" XXX\n'
                    'VAL_ 1275 _0_COUNTER 1 "one" ;')
    assert [r.line for r in repairs] == [1, 2] and "'2017_5'" in repairs[0].what


def test_an_id_above_11_bits_is_flagged_extended_on_every_statement_and_one_above_29_bits_is_dropped():
    source = ('BO_ 103596083 BSM: 8 XXX\n SG_ LEFT : 7|1@0+ (1,0) [0|1] "" XXX\n\n'
              'BO_ 1075054137 REF: 8 CGW\n SG_ A : 7|8@0+ (1,0) [0|255] "" XXX\n SG_ B : 15|8@0+ (1,0) [0|255] "" XXX\n'
              '\nBO_ 100 OK: 8 XXX\n SG_ C : 7|8@0+ (1,0) [0|255] "" XXX\n'
              'CM_ SG_ 103596083 LEFT "blind spot";\nCM_ BO_ 1075054137 "a\ncomment";\nVAL_ 1075054137 A 1 "on" ;\n'
              'BA_ "GenMsgCycleTime" BO_ 103596083 100;')
    text, repairs = repaired(dbc_repair.long_standard_ids, source)
    flagged = str(103596083 | dbc_repair.EXTENDED_FLAG)
    assert text.split("\n") == [
        f"BO_ {flagged} BSM: 8 XXX", ' SG_ LEFT : 7|1@0+ (1,0) [0|1] "" XXX', "",
        "", "", "", "", "BO_ 100 OK: 8 XXX", ' SG_ C : 7|8@0+ (1,0) [0|255] "" XXX',
        f'CM_ SG_ {flagged} LEFT "blind spot";', "", "", "", f'BA_ "GenMsgCycleTime" BO_ {flagged} 100;']
    assert [r.line for r in repairs] == [1, 4, 10, 11, 13, 14]
    assert {r.dropped_message for r in repairs} == {"", "REF"}


def test_value_tables_cantools_names_unused_are_dropped():
    error = 'DBC: "unused VAL_ entries in DBC:\n    VAL_ 715 GasInv\n    VAL_ 1157 HDA"'
    text, repairs = repaired(dbc_repair.unused_value_tables, 'VAL_ 715 GasInv 1 "x" ;\nVAL_ 715 Gas 1 "x" ;\n'
                                                            'VAL_ 1157 HDA 0 "off" ;', error)
    assert text == '\nVAL_ 715 Gas 1 "x" ;\n' and [r.line for r in repairs] == [1, 3]
    assert repaired(dbc_repair.unused_value_tables, 'VAL_ 715 GasInv 1 "x" ;', "Invalid syntax")[1] == []


def test_the_loader_repairs_a_dbc_cantools_refuses_and_warns_naming_file_line_and_repair(tmp_path, caplog):
    dbc = tmp_path / "car.dbc"
    dbc.write_text(HEADER + MESSAGE + 'BO_ 100 SPEED: 8 XXX\n SG_ V : 7|16@0+ (.01,0) [0|655.35] "km/h" XXX\n\n'
                   'CM_ SG_ 304 "no signal named";\nVAL_ 304 GONE 1 "on" ;\n')
    with caplog.at_level(logging.WARNING, logger="canest.dbc"):
        database = load_database(dbc, "test")
    assert database.get_message_by_name("SPEED").get_signal_by_name("V").scale == 0.01
    assert database.get_message_by_name("GAS").comment == "no signal named"
    warnings = [record.getMessage() for record in caplog.records]
    assert len(warnings) == 3
    assert warnings[0].startswith(f"{dbc}:9: number without a digit")
    assert warnings[1].startswith(f"{dbc}:11: signal comment without a signal name")
    assert warnings[2].startswith(f"{dbc}:12: value table of GONE")
    assert tolerated_problems(dbc, "test")[""].startswith("3 lines repaired before parsing: line 9:")


def test_a_dbc_no_repair_fixes_is_still_one_error_naming_the_file(tmp_path):
    dbc = tmp_path / "bad.dbc"
    dbc.write_text(HEADER + "BO_ this is no DBC\n")
    with pytest.raises(DbcError, match=f"{dbc}: cannot load DBC \\(referenced by test\\): .*line 5"):
        load_database(dbc, "test")


def test_every_dbc_opendbc_ships_loads(tmp_path):
    opendbc = pytest.importorskip("opendbc", reason="opendbc is not installed: pip install 'canest[opendbc]'")
    paths = sorted(Path(opendbc.DBC_PATH).glob("*.dbc"))
    for name, text in sorted(opendbc.get_generated_dbcs().items()):
        paths.append(tmp_path / f"{name}.dbc")
        paths[-1].write_text(text)
    failures = {}
    for path in paths:
        try:
            load_database(path, "test")
        except DbcError as exc:
            failures[path.name] = str(exc)
    print(f"\n{len(paths) - len(failures)} of {len(paths)} opendbc DBCs load")
    assert len(paths) >= 90 and failures == {}
