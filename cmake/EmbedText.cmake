# Writes OUTPUT as a header defining `inline constexpr char SYMBOL[]` with the contents of INPUT.
file(READ ${INPUT} CONTENT)
set(DELIM "mp_embed_")
file(WRITE ${OUTPUT} "// Generated from ${INPUT}; do not edit.\n#pragma once\ninline constexpr char ${SYMBOL}[] = R\"${DELIM}(${CONTENT})${DELIM}\";\n")
