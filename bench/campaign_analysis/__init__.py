"""A campaign as the unit of analysis: every run of one or more campaign folders analysed in parallel into
one Parquet table (``hilbench analyse``), and the campaign page. docs/campaign-analysis.md."""
