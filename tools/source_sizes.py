#!/usr/bin/env python3
"""Files and functions past the house limits: no file under src/ over LINES lines, no function
over FUNC lines (a brace-matching reading of C++: comments and strings blanked, a function is an
outermost brace block whose opening statement has a parameter list and is not a control
statement, a lambda or an initializer).

    tools/source_sizes.py [--root DIR] [--file-lines 700] [--function-lines 150] [--list N]

Exit 1 naming each file and function past its limit, 0 when none is; --list N prints every
function over N lines as well (a report, not a check)."""

import argparse
import pathlib
import re
import sys

CONTROL = re.compile(r'^\s*(if|for|while|switch|catch|do|else|try|namespace|struct|class|enum|union|extern)\b')
LAMBDA = re.compile(r'\]\s*(\([^)]*\))?\s*(mutable\s*)?(noexcept\s*)?(->[^{]*)?$')


def blank(text):
    """The text with comments, string and character literals blanked (line count kept)."""
    keep_lines = lambda m: '\n' * m.group(0).count('\n')
    text = re.sub(r'R"(\w*)\((.*?)\)\1"', lambda m: '""' + keep_lines(m), text, flags=re.S)
    text = re.sub(r'/\*.*?\*/', keep_lines, text, flags=re.S)
    text = re.sub(r'//[^\n]*', '', text)
    text = re.sub(r'"(\\.|[^"\\\n])*"', '""', text)
    return re.sub(r"'(\\.|[^'\\\n])'", "''", text)


def functions(path):
    """(first line, lines, signature) of each outermost function body in the file."""
    out = []
    stack = []  # (line, is_function)
    stmt = ''
    for number, line in enumerate(blank(path.read_text(errors='replace')).split('\n'), start=1):
        for ch in line:
            if ch == '{':
                s = ' '.join(stmt.split())
                is_fn = ('(' in s and ')' in s and not CONTROL.match(s) and not LAMBDA.search(s)
                         and not s.endswith('=') and '=' not in s.split('(')[0])
                inside_fn = any(f for _, f, _ in stack)
                stack.append((number, is_fn and not inside_fn, s[-100:]))
                stmt = ''
            elif ch == '}':
                if stack:
                    start, is_fn, s = stack.pop()
                    if is_fn:
                        out.append((start, number - start + 1, s))
                stmt = ''
            elif ch == ';':
                stmt = ''
            else:
                stmt += ch
        stmt += ' '
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--root', default=str(pathlib.Path(__file__).resolve().parent.parent))
    ap.add_argument('--file-lines', type=int, default=700)
    ap.add_argument('--function-lines', type=int, default=150)
    ap.add_argument('--list', type=int, default=0, help='also print every function over N lines')
    a = ap.parse_args()
    src = pathlib.Path(a.root) / 'src'
    files = sorted(p for p in src.rglob('*') if p.suffix in ('.cpp', '.h', '.hpp', '.cc'))
    if not files:
        print(f'source_sizes: no sources under {src}', file=sys.stderr)
        return 2
    over = []
    for p in files:
        rel = p.relative_to(a.root)
        lines = p.read_text(errors='replace').count('\n')
        if lines > a.file_lines:
            over.append(f'{rel}: {lines} lines (limit {a.file_lines})')
        for start, n, sig in functions(p):
            if n > a.function_lines:
                over.append(f'{rel}:{start}: a function of {n} lines (limit {a.function_lines}): {sig}')
            elif a.list and n > a.list:
                print(f'{rel}:{start}: {n} lines: {sig}')
    for o in over:
        print(o)
    return 1 if over else 0


if __name__ == '__main__':
    sys.exit(main())
